//! antimatter15's `.splat` (what most web viewers and many capture apps export): no header,
//! 32 bytes a splat, little-endian: the position (3 × f32), the linear scale (3 × f32), the
//! colour and opacity as RGBA bytes (the colour as the viewer shows it, sRGB-encoded, so the
//! DC coefficient is `(c/255 − 0.5)/Y₀⁰`; the opacity `a/255`), and the rotation as four bytes
//! `w x y z`, each `(q − 128)/128`, normalised. There is no view-dependent colour (SH
//! degree 0).
//!
//! The file is read as a stream of records, never whole.

use std::io::{BufReader, Read};
use std::path::Path;

use glam::Vec3;

use super::{dc_from_color, SplatFormat};
use crate::error::{Error, Result};
use crate::field::splats::{SplatColor, Splats};

/// Bytes a splat.
pub(crate) const RECORD: usize = 32;

/// Reads the `.splat` file at `path`.
pub(crate) fn read(path: &Path) -> Result<Splats> {
    let (file, len) = crate::input::open_regular(path)?;
    let reader = BufReader::with_capacity(1 << 16, file.take(len));
    from_reader(path, reader, len)
}

/// Splats from the bytes of a `.splat` file (`path` for messages).
#[cfg(test)]
pub(crate) fn parse(path: &Path, bytes: &[u8]) -> Result<Splats> {
    from_reader(path, bytes, bytes.len() as u64)
}

fn from_reader(path: &Path, mut reader: impl Read, len: u64) -> Result<Splats> {
    if len == 0 {
        return Err(Error::format(
            path,
            "",
            "is empty: a .splat holds 32 bytes a splat",
        ));
    }
    if !len.is_multiple_of(RECORD as u64) {
        return Err(Error::format(
            path,
            format!("splat {}", len / RECORD as u64),
            format!(
                "the file is {len} bytes, not a whole number of 32-byte splats: truncated, or \
                 not a .splat file"
            ),
        ));
    }
    let n = usize::try_from(len / RECORD as u64).unwrap_or(usize::MAX);
    let mut splats = Splats::with_capacity(n, SplatColor::Sh { degree: 0 }, SplatFormat::Splat);
    splats.source.quantisation = "positions and scales 32-bit floats; colour and opacity 8 bits; \
                                  rotation 8 bits a component"
        .into();
    let mut record = [0u8; RECORD];
    for i in 0..n {
        reader.read_exact(&mut record).map_err(|e| {
            Error::format(path, format!("splat {i}"), format!("cannot be read: {e}"))
        })?;
        let s = decode(&record);
        if !splats.push_activated(s.mean, s.scale, s.wxyz, s.opacity, &s.dc) {
            splats.dropped += 1;
        }
    }
    Ok(splats)
}

/// One decoded record.
pub(crate) struct Record {
    pub mean: Vec3,
    pub scale: Vec3,
    /// The rotation `w x y z`, not yet normalised.
    pub(crate) wxyz: [f32; 4],
    pub opacity: f32,
    pub(crate) dc: [f32; 3],
}

/// Decodes one 32-byte record.
pub(crate) fn decode(r: &[u8; RECORD]) -> Record {
    let f = |at: usize| f32::from_le_bytes([r[at], r[at + 1], r[at + 2], r[at + 3]]);
    let q = |at: usize| (f32::from(r[at]) - 128.0) / 128.0;
    Record {
        mean: Vec3::new(f(0), f(4), f(8)),
        scale: Vec3::new(f(12), f(16), f(20)),
        wxyz: [q(28), q(29), q(30), q(31)],
        opacity: f32::from(r[27]) / 255.0,
        dc: [24, 25, 26].map(|at| dc_from_color(f32::from(r[at]) / 255.0)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(mean: [f32; 3], scale: [f32; 3], rgba: [u8; 4], rot: [u8; 4]) -> [u8; 32] {
        let mut r = [0u8; 32];
        for (k, v) in mean.iter().chain(&scale).enumerate() {
            r[4 * k..4 * k + 4].copy_from_slice(&v.to_le_bytes());
        }
        r[24..28].copy_from_slice(&rgba);
        r[28..32].copy_from_slice(&rot);
        r
    }

    #[test]
    fn records_decode_as_the_format_describes() {
        let mut bytes = record(
            [1.0, -2.0, 3.5],
            [0.01, 0.02, 0.5],
            [255, 0, 128, 51],
            [255, 128, 128, 128],
        )
        .to_vec();
        // Rotation half a turn about z: w = 0, z = 1 → bytes (128, 128, 128, 255).
        bytes.extend(record(
            [0.0; 3],
            [1.0; 3],
            [10, 20, 30, 255],
            [128, 128, 128, 255],
        ));
        let s = parse(Path::new("t.splat"), &bytes).unwrap();
        assert_eq!(s.len(), 2);
        assert_eq!(s.means[0], Vec3::new(1.0, -2.0, 3.5));
        assert_eq!(s.scales[0], Vec3::new(0.01, 0.02, 0.5));
        assert!((s.opacities[0] - 0.2).abs() < 1e-7);
        assert_eq!(s.opacities[1], 1.0);
        // The DC coefficients display the stored colour: 0.5 + Y₀·k = c/255.
        for (k, c) in s.coefficients[..3].iter().zip([255.0, 0.0, 128.0]) {
            assert!((0.5 + 0.282_094_8 * k - c / 255.0).abs() < 1e-6);
        }
        assert!(s.rotations[0].abs_diff_eq(glam::Quat::IDENTITY, 1e-6));
        assert!(s.rotations[1].abs_diff_eq(glam::Quat::from_xyzw(0.0, 0.0, 1.0, 0.0), 1e-6));
    }

    #[test]
    fn truncated_and_empty_files_are_refused_naming_the_splat() {
        let bytes = record([0.0; 3], [1.0; 3], [0; 4], [255, 128, 128, 128]);
        let e = parse(Path::new("t.splat"), &bytes[..20])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("t.splat") && e.contains("splat 0") && e.contains("20 bytes"),
            "{e}"
        );
        let e = parse(Path::new("t.splat"), &[]).unwrap_err().to_string();
        assert!(e.contains("empty"), "{e}");
    }

    #[test]
    fn zero_rotations_and_non_finite_values_are_dropped_and_counted() {
        let mut bytes = record([0.0; 3], [1.0; 3], [0; 4], [128; 4]).to_vec();
        bytes.extend(record(
            [f32::NAN, 0.0, 0.0],
            [1.0; 3],
            [0; 4],
            [255, 128, 128, 128],
        ));
        bytes.extend(record([0.0; 3], [1.0; 3], [0; 4], [255, 128, 128, 128]));
        let s = parse(Path::new("t.splat"), &bytes).unwrap();
        assert_eq!((s.len(), s.dropped), (1, 2));
    }
}
