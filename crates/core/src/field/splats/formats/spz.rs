//! Niantic's SPZ (what Scaniverse exports), versions 2, 3 and 4, as its reference library
//! (nianticlabs/spz) writes them.
//!
//! A header gives the version, the splat count, the SH degree (0–4), the number of fractional
//! bits of the positions and flags (bit 0: trained antialiased; bit 1: extensions follow).
//! Then come the attributes, each for every splat in turn: positions (3 × 24-bit signed fixed
//! point), alphas (a byte, the opacity `a/255`), colours (3 bytes, the DC coefficient
//! `(c/255 − 0.5)/0.15`), scales (3 bytes, the log scale `s/16 − 10`), rotations and SH
//! coefficients (bytes, `(v − 128)/128`, coefficient by coefficient, r g b each).
//!
//! - Versions 2 and 3: the file is one gzip stream of a 16-byte header and the attributes.
//!   Version 2's rotations are `x y z` in a byte each (`r/127.5 − 1`, `w = √(1 − |xyz|²)`);
//!   version 3 packs the smallest three in 32 bits (the largest's index in the 2 highest bits,
//!   then for each other component, from `z` down, a sign bit and 9 bits of `|q|·√2`).
//! - Version 4: a plain 32-byte header (adding the stream count and the byte offset of a table
//!   of contents), the table (compressed and uncompressed size of each stream, 8 bytes each),
//!   then each non-empty attribute as its own zstd stream; rotations as in version 3.
//!
//! Version 1 (half-float positions) is refused by name. SPZ says nothing about its axes (see
//! [`Axes`](crate::field::Axes)): the stored values are read as they are. Every stream is
//! inflated only up to the size the header's count gives it, and the count itself is bounded
//! by what the file's size can decompress to, so a small file cannot claim a huge cloud.

use std::io::{BufReader, Read};
use std::path::Path;

use flate2::read::GzDecoder;
use glam::Vec3;

use super::SplatFormat;
use crate::error::{Error, Result};
use crate::field::splats::{SplatColor, Splats};

/// The DC colour scale of the reference library.
const COLOR_SCALE: f32 = 0.15;
/// `NGSP`, little-endian.
const MAGIC: u32 = 0x5053_474e;
/// Flag bit: trained with antialiasing (mip-splatting).
const FLAG_ANTIALIASED: u8 = 1;
/// The most a deflate stream expands (its longest match, 258 bytes, in about two bits).
const DEFLATE_MAX_RATIO: u64 = 1032;
/// A generous bound on zstd's expansion, as the reference library uses for the same check.
const ZSTD_MAX_RATIO: u64 = 1024;

/// What the header says.
#[derive(Clone, Copy, Debug)]
struct Header {
    version: u32,
    count: usize,
    sh_degree: u8,
    fractional_bits: u8,
    flags: u8,
}

impl Header {
    /// Higher SH coefficients a splat, per channel, as stored.
    fn sh_dim(&self) -> usize {
        (usize::from(self.sh_degree) + 1).pow(2) - 1
    }

    fn rotation_bytes(&self) -> usize {
        if self.version >= 3 {
            4
        } else {
            3
        }
    }

    /// Bytes a splat, over all attributes.
    fn bytes_per_splat(&self) -> usize {
        9 + 1 + 3 + 3 + self.rotation_bytes() + 3 * self.sh_dim()
    }

    /// Checks what the header says against what the reader and a file of `file_bytes`
    /// compressed by at most `ratio` can hold.
    fn check(&self, path: &Path, raw_count: u32, file_bytes: u64, ratio: u64) -> Result<()> {
        let bad = |m: String| Err(Error::format(path, "header", m));
        if self.sh_degree > 4 {
            return bad(format!("SH degree {}; SPZ holds 0 to 4", self.sh_degree));
        }
        if self.fractional_bits > 24 {
            return bad(format!(
                "{} fractional bits for 24-bit positions",
                self.fractional_bits
            ));
        }
        if raw_count == 0 {
            return bad("holds no splats".into());
        }
        let most = file_bytes.saturating_mul(ratio) / self.bytes_per_splat() as u64;
        if u64::from(raw_count) > most {
            return bad(format!(
                "declares {raw_count} splats, more than a file of {file_bytes} bytes can hold \
                 ({most} at most)"
            ));
        }
        Ok(())
    }
}

fn refuse_version(path: &Path, version: u32) -> Error {
    let why = if version == 1 {
        " (half-float positions, an early format); re-save it with Niantic's spz tools"
    } else {
        ""
    };
    Error::Unsupported(format!(
        "{}: SPZ version {version}{why}; nerfx reads SPZ versions 2, 3 and 4",
        path.display()
    ))
}

/// Reads the SPZ file at `path`.
pub(crate) fn read(path: &Path) -> Result<Splats> {
    let (file, len) = crate::input::open_regular(path)?;
    let mut reader = BufReader::with_capacity(1 << 16, file.take(len));
    let mut magic = [0u8; 2];
    reader
        .read_exact(&mut magic)
        .map_err(|e| Error::format(path, "header", format!("cannot be read: {e}")))?;
    if magic == [0x1f, 0x8b] {
        let stream = magic.as_slice().chain(reader);
        return from_gzip(path, stream, len);
    }
    // Version 4 needs its table of contents and random access: read it whole.
    let bytes = crate::input::read_bytes(path)?;
    from_ngsp(path, &bytes)
}

/// Splats from the bytes of an SPZ file (`path` for messages).
#[cfg(test)]
pub(crate) fn parse(path: &Path, bytes: &[u8]) -> Result<Splats> {
    if bytes.starts_with(&[0x1f, 0x8b]) {
        from_gzip(path, bytes, bytes.len() as u64)
    } else {
        from_ngsp(path, bytes)
    }
}

/// The packed attributes, each for every splat.
struct Packed {
    positions: Vec<u8>,
    alphas: Vec<u8>,
    colors: Vec<u8>,
    scales: Vec<u8>,
    rotations: Vec<u8>,
    sh: Vec<u8>,
}

const ATTRIBUTES: [&str; 6] = [
    "positions",
    "alphas",
    "colours",
    "scales",
    "rotations",
    "spherical harmonics",
];

impl Packed {
    fn sizes(h: &Header) -> [usize; 6] {
        let n = h.count;
        [
            9 * n,
            n,
            3 * n,
            3 * n,
            h.rotation_bytes() * n,
            3 * h.sh_dim() * n,
        ]
    }
}

/// Reads exactly `size` bytes of `attribute` from `stream`, memory growing only with what the
/// stream really holds.
fn read_attribute(
    path: &Path,
    stream: &mut impl Read,
    size: usize,
    attribute: &str,
) -> Result<Vec<u8>> {
    let mut data = Vec::with_capacity(size.min(1 << 20));
    stream
        .take(size as u64)
        .read_to_end(&mut data)
        .map_err(|e| Error::format(path, attribute, format!("cannot be decompressed: {e}")))?;
    if data.len() != size {
        return Err(Error::format(
            path,
            attribute,
            format!(
                "truncated: the stream ends after {} of its {size} bytes",
                data.len()
            ),
        ));
    }
    Ok(data)
}

/// Versions 2 and 3 (and 4 written the older way): one gzip stream.
fn from_gzip(path: &Path, stream: impl Read, file_bytes: u64) -> Result<Splats> {
    let mut gz = GzDecoder::new(stream);
    let mut h = [0u8; 16];
    gz.read_exact(&mut h)
        .map_err(|e| Error::format(path, "header", format!("cannot be decompressed: {e}")))?;
    let word = |at: usize| u32::from_le_bytes([h[at], h[at + 1], h[at + 2], h[at + 3]]);
    if word(0) != MAGIC {
        return Err(Error::format(
            path,
            "header",
            "no 'NGSP' signature inside the gzip stream: not an SPZ file",
        ));
    }
    let version = word(4);
    if !(2..=4).contains(&version) {
        return Err(refuse_version(path, version));
    }
    let raw_count = word(8);
    let header = Header {
        version,
        count: raw_count as usize,
        sh_degree: h[12],
        fractional_bits: h[13],
        flags: h[14],
    };
    header.check(path, raw_count, file_bytes, DEFLATE_MAX_RATIO)?;
    let sizes = Packed::sizes(&header);
    let mut parts = Vec::with_capacity(6);
    for (size, name) in sizes.iter().zip(ATTRIBUTES) {
        parts.push(read_attribute(path, &mut gz, *size, name)?);
    }
    // Extensions (flag bit 1) may follow; nothing in them changes how splats decode.
    decode(header, into_packed(parts))
}

fn into_packed(parts: Vec<Vec<u8>>) -> Packed {
    let mut it = parts.into_iter();
    let mut next = || it.next().unwrap_or_default();
    Packed {
        positions: next(),
        alphas: next(),
        colors: next(),
        scales: next(),
        rotations: next(),
        sh: next(),
    }
}

/// Version 4: a plain header, a table of contents and one zstd stream an attribute.
fn from_ngsp(path: &Path, bytes: &[u8]) -> Result<Splats> {
    if bytes.len() < 32 {
        return Err(Error::format(
            path,
            "header",
            format!(
                "truncated: {} bytes, the SPZ header alone is 32",
                bytes.len()
            ),
        ));
    }
    let word =
        |at: usize| u32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]);
    if word(0) != MAGIC {
        return Err(Error::format(path, "header", "not an SPZ file"));
    }
    let version = word(4);
    if version != 4 {
        if version == 2 || version == 3 {
            return Err(Error::format(
                path,
                "header",
                format!("SPZ version {version} without its gzip stream: the file is damaged"),
            ));
        }
        return Err(refuse_version(path, version));
    }
    let raw_count = word(8);
    let header = Header {
        version,
        count: raw_count as usize,
        sh_degree: bytes[12],
        fractional_bits: bytes[13],
        flags: bytes[14],
    };
    header.check(path, raw_count, bytes.len() as u64, ZSTD_MAX_RATIO)?;
    let streams = usize::from(bytes[15]);
    let toc = word(16) as usize;
    let sizes = Packed::sizes(&header);
    let present: Vec<usize> = (0..6).filter(|&k| sizes[k] > 0).collect();
    if streams != present.len() {
        return Err(Error::format(
            path,
            "header",
            format!(
                "{streams} streams; splats of SH degree {} need {}",
                header.sh_degree,
                present.len()
            ),
        ));
    }
    let toc_end = toc
        .checked_add(16 * streams)
        .filter(|&e| toc >= 32 && e <= bytes.len());
    let Some(toc_end) = toc_end else {
        return Err(Error::format(
            path,
            "table of contents",
            format!(
                "at byte {toc} lies outside the file of {} bytes",
                bytes.len()
            ),
        ));
    };
    let long = |at: usize| {
        let mut b = [0u8; 8];
        b.copy_from_slice(&bytes[at..at + 8]);
        u64::from_le_bytes(b)
    };
    let mut parts = vec![Vec::new(); 6];
    let mut offset = toc_end;
    for (i, &k) in present.iter().enumerate() {
        let name = ATTRIBUTES[k];
        let (compressed, uncompressed) = (long(toc + 16 * i), long(toc + 16 * i + 8));
        if uncompressed != sizes[k] as u64 {
            return Err(Error::format(
                path,
                name,
                format!(
                    "the table gives {uncompressed} bytes; {} splats need {}",
                    header.count, sizes[k]
                ),
            ));
        }
        let end = usize::try_from(compressed)
            .ok()
            .and_then(|c| offset.checked_add(c))
            .filter(|&e| e <= bytes.len())
            .ok_or_else(|| {
                Error::format(
                    path,
                    name,
                    "truncated: the stream runs past the end of the file",
                )
            })?;
        let mut zstd = ruzstd::decoding::StreamingDecoder::new(&bytes[offset..end])
            .map_err(|e| Error::format(path, name, format!("not a zstd stream: {e}")))?;
        parts[k] = read_attribute(path, &mut zstd, sizes[k], name)?;
        offset = end;
    }
    decode(header, into_packed(parts))
}

/// Decodes the packed attributes.
fn decode(h: Header, p: Packed) -> Result<Splats> {
    let n = h.count;
    let stored_degree = h.sh_degree;
    let degree = stored_degree.min(3);
    let color = SplatColor::Sh { degree };
    let kept = (usize::from(degree) + 1).pow(2) - 1;
    let dim = h.sh_dim();
    let mut splats = Splats::with_capacity(n, color, SplatFormat::Spz);
    splats.source.version = Some(h.version);
    splats.source.antialiased = h.flags & FLAG_ANTIALIASED != 0;
    splats.source.quantisation = format!(
        "positions 24-bit fixed point with {} fractional bits ({:.2e} units), opacity, colour \
         and log scale 8 bits, rotations {}, SH degree {stored_degree} in 8 bits",
        h.fractional_bits,
        2f32.powi(-i32::from(h.fractional_bits)),
        if h.version >= 3 {
            "smallest-three in 32 bits"
        } else {
            "x y z in 8 bits each"
        },
    );
    if stored_degree > 3 {
        splats.source.notes.push(format!(
            "the file holds SH degree {stored_degree}; nerfx renders up to degree 3 and leaves \
             the higher band out"
        ));
    }
    let unit = 2f32.powi(-i32::from(h.fractional_bits));
    let fixed = |b: &[u8]| {
        let v = i32::from(b[0]) | (i32::from(b[1]) << 8) | (i32::from(b[2]) << 16);
        // Sign-extend the 24 bits.
        ((v << 8) >> 8) as f32 * unit
    };
    let mut coeffs = vec![0.0f32; color.coefficients() * 3];
    let rb = h.rotation_bytes();
    for i in 0..n {
        let pos = &p.positions[9 * i..9 * i + 9];
        let mean = Vec3::new(fixed(&pos[0..3]), fixed(&pos[3..6]), fixed(&pos[6..9]));
        let s = &p.scales[3 * i..3 * i + 3];
        let log_scale = Vec3::new(s[0].into(), s[1].into(), s[2].into()) / 16.0 - Vec3::splat(10.0);
        let r = &p.rotations[rb * i..rb * (i + 1)];
        let xyzw = if h.version >= 3 {
            smallest_three([r[0], r[1], r[2], r[3]])
        } else {
            first_three([r[0], r[1], r[2]])
        };
        let opacity = f32::from(p.alphas[i]) / 255.0;
        for (k, c) in coeffs[..3].iter_mut().zip(&p.colors[3 * i..3 * i + 3]) {
            *k = (f32::from(*c) / 255.0 - 0.5) / COLOR_SCALE;
        }
        let sh = &p.sh[3 * dim * i..3 * dim * (i + 1)];
        for k in 0..kept {
            for c in 0..3 {
                coeffs[(k + 1) * 3 + c] = (f32::from(sh[k * 3 + c]) - 128.0) / 128.0;
            }
        }
        let [x, y, z, w] = xyzw;
        if !splats.push_activated(mean, log_scale.exp(), [w, x, y, z], opacity, &coeffs) {
            splats.dropped += 1;
        }
    }
    Ok(splats)
}

/// Version 2's rotation: `x y z` in a byte each, `w` non-negative. Returns `x y z w`.
fn first_three(r: [u8; 3]) -> [f32; 4] {
    let xyz = r.map(|b| f32::from(b) / 127.5 - 1.0);
    let w = (1.0 - xyz.iter().map(|v| v * v).sum::<f32>())
        .max(0.0)
        .sqrt();
    [xyz[0], xyz[1], xyz[2], w]
}

/// Version 3's smallest-three rotation in 32 bits. Returns `x y z w`.
fn smallest_three(r: [u8; 4]) -> [f32; 4] {
    let mut comp = u32::from_le_bytes(r);
    let largest = (comp >> 30) as usize;
    let mut q = [0.0f32; 4];
    let mut sum = 0.0;
    for i in (0..4).rev() {
        if i != largest {
            let magnitude = (comp & 0x1ff) as f32 / 511.0 * std::f32::consts::FRAC_1_SQRT_2;
            let negative = (comp >> 9) & 1 == 1;
            comp >>= 10;
            q[i] = if negative { -magnitude } else { magnitude };
            sum += q[i] * q[i];
        }
    }
    q[largest] = (1.0 - sum).max(0.0).sqrt();
    q
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotations_decode_as_the_reference_packs_them() {
        // Identity: v2 x y z at 127.5 → bytes 128 (w from the rest).
        let q = first_three([128, 128, 128]);
        assert!((q[3] - 1.0).abs() < 1e-4, "{q:?}");
        // Smallest three: w largest (index 3), x = +½, y = −½, z = 0 packed from x (highest)
        // down to z (lowest).
        let m = (0.5 / std::f32::consts::FRAC_1_SQRT_2 * 511.0 + 0.5) as u32;
        let comp = (3u32 << 30) | (m << 20) | ((1 << 9 | m) << 10);
        let q = smallest_three(comp.to_le_bytes());
        assert!(
            (q[0] - 0.5).abs() < 2e-3 && (q[1] + 0.5).abs() < 2e-3 && q[2] == 0.0,
            "{q:?}"
        );
        assert!((q[3] - 0.5f32.sqrt()).abs() < 3e-3, "{q:?}");
    }

    #[test]
    fn version_one_and_unknown_versions_are_refused_by_name() {
        let mut h = Vec::new();
        h.extend_from_slice(&MAGIC.to_le_bytes());
        h.extend_from_slice(&1u32.to_le_bytes());
        h.extend_from_slice(&[0; 24]);
        let e = parse(Path::new("old.spz"), &h).unwrap_err().to_string();
        assert!(e.contains("old.spz") && e.contains("version 1"), "{e}");
        h[4] = 9;
        let e = parse(Path::new("new.spz"), &h).unwrap_err().to_string();
        assert!(e.contains("version 9") && e.contains("2, 3 and 4"), "{e}");
    }
}
