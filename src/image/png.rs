//! 8-bit PNG previews of render planes, encoded by hand (the format is small: a signature and
//! three chunk kinds), with zlib from `flate2`.
//!
//! A PNG is the 8-byte signature, then chunks `length (u32 BE) | type | data | CRC-32(type ‖
//! data)`: `IHDR` (size, 8 bits, colour type 6 = RGBA), `IDAT` (the zlib stream of the rows,
//! each row prefixed by its filter byte; 0 = none here) and an empty `IEND`.

use std::io::Write;
use std::path::Path;

use flate2::write::ZlibEncoder;
use flate2::{Compression, Crc};

use crate::error::{Error, Result};
use crate::image::{Plane, Planes, BACKGROUND_DEPTH};

/// The 8 bytes every PNG starts with.
const SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', 0x0D, 0x0A, 0x1A, 0x0A];

/// PNG's largest width or height, 2³¹ − 1.
const MAX_SIDE: u32 = i32::MAX as u32;

/// Writes an 8-bit RGBA preview of `planes` to `path`, for a quick look (the EXR is the data).
///
/// What is shown, by the first present of:
/// - `rgb`: un-premultiplied (`c / α` where `α > 0`, as is where `α = 0`) and sRGB-encoded,
///   with `alpha` as the PNG's (linear) alpha, opaque when there is no alpha;
/// - `alpha`: a grey matte, value `α` (linear, as mattes are viewed);
/// - a depth plane (`depth_z`, else `depth_ray`, else `depth_median`): grey, linear from 255
///   at the nearest hit to 0 at the farthest; misses (`inf`, or ≥ [`BACKGROUND_DEPTH`]) black.
///
/// Values are clamped to [0, 1] and rounded to the nearest of 256 levels; NaN gives 0.
///
/// Errors: [`Error::Invalid`] when no plane is present or the image is empty or too large for
/// PNG; [`Error::Io`] naming `path` when the file cannot be written.
pub fn write_png_preview(path: &Path, planes: &Planes) -> Result<()> {
    let rgba = preview_rgba8(planes)?;
    let bytes = encode_png_rgba8(planes.width, planes.height, &rgba)?;
    super::replace::replace_file(path, |temp| {
        std::fs::write(temp, bytes).map_err(|e| Error::io(path, e))
    })
}

/// Encodes `rgba` (`width × height` pixels, 4 bytes each, rows top first, non-premultiplied
/// alpha) as a complete PNG file.
///
/// Errors: [`Error::Invalid`] when a side is 0 or above 2³¹ − 1, or `rgba` has the wrong length.
pub fn encode_png_rgba8(width: u32, height: u32, rgba: &[u8]) -> Result<Vec<u8>> {
    if width == 0 || height == 0 || width > MAX_SIDE || height > MAX_SIDE {
        return Err(Error::invalid(
            "PNG image",
            format!("size {width}×{height} is outside 1..2³¹−1"),
        ));
    }
    let row_bytes = width as usize * 4;
    if rgba.len() != row_bytes * height as usize {
        return Err(Error::invalid(
            "PNG image",
            format!(
                "{} bytes of RGBA for {width}×{height} pixels (expected {})",
                rgba.len(),
                row_bytes * height as usize
            ),
        ));
    }

    let mut ihdr = Vec::with_capacity(13);
    ihdr.extend_from_slice(&width.to_be_bytes());
    ihdr.extend_from_slice(&height.to_be_bytes());
    // Bit depth 8, colour type 6 (RGBA), deflate, adaptive filtering, no interlace.
    ihdr.extend_from_slice(&[8, 6, 0, 0, 0]);

    let mut zlib = ZlibEncoder::new(Vec::new(), Compression::default());
    let deflated = rgba
        .chunks_exact(row_bytes)
        .try_for_each(|row| {
            zlib.write_all(&[0])?; // filter type 0: the row as is
            zlib.write_all(row)
        })
        .and_then(|()| zlib.finish())
        .map_err(|e| Error::invalid("PNG image", format!("deflate failed: {e}")))?;

    let mut png = Vec::with_capacity(SIGNATURE.len() + deflated.len() + 3 * 12 + 13);
    png.extend_from_slice(&SIGNATURE);
    push_chunk(&mut png, b"IHDR", &ihdr);
    push_chunk(&mut png, b"IDAT", &deflated);
    push_chunk(&mut png, b"IEND", &[]);
    Ok(png)
}

/// Appends one chunk: length, type, data, CRC-32 over type and data.
fn push_chunk(png: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
    // PNG caps a chunk at 2³¹ − 1 bytes; the deflated rows of the largest image we could
    // hold in memory stay far below (a 2³¹-byte IDAT is an 8-gigapixel-ish image).
    png.extend_from_slice(&(data.len() as u32).to_be_bytes());
    png.extend_from_slice(kind);
    png.extend_from_slice(data);
    let mut crc = Crc::new();
    crc.update(kind);
    crc.update(data);
    png.extend_from_slice(&crc.sum().to_be_bytes());
}

/// The RGBA8 pixels of the preview described at [`write_png_preview`].
fn preview_rgba8(planes: &Planes) -> Result<Vec<u8>> {
    let n = planes.width as usize * planes.height as usize;
    let present = [
        planes.rgb.as_ref().map(|rgb| &rgb[0]),
        planes.rgb.as_ref().map(|rgb| &rgb[1]),
        planes.rgb.as_ref().map(|rgb| &rgb[2]),
        planes.alpha.as_ref(),
        planes.depth_z.as_ref(),
        planes.depth_ray.as_ref(),
        planes.depth_median.as_ref(),
    ];
    if let Some(bad) = present.iter().flatten().find(|p| p.data.len() != n) {
        return Err(Error::invalid(
            "PNG preview",
            format!(
                "a plane has {} samples, the image is {}×{}",
                bad.data.len(),
                planes.width,
                planes.height
            ),
        ));
    }
    let depth = planes
        .depth_z
        .as_ref()
        .or(planes.depth_ray.as_ref())
        .or(planes.depth_median.as_ref());
    let pixels: Vec<[u8; 4]> = match (&planes.rgb, &planes.alpha, depth) {
        (Some([r, g, b]), alpha, _) => (0..n)
            .map(|i| {
                let a = alpha.as_ref().map_or(1.0, |p| p.data[i]);
                let un = |c: f32| if a > 0.0 { c / a } else { c };
                [
                    srgb_u8(un(r.data[i])),
                    srgb_u8(un(g.data[i])),
                    srgb_u8(un(b.data[i])),
                    linear_u8(a),
                ]
            })
            .collect(),
        (None, Some(alpha), _) => alpha.data.iter().map(|&a| grey(linear_u8(a))).collect(),
        (None, None, Some(depth)) => depth_preview(depth),
        (None, None, None) => {
            return Err(Error::invalid("PNG preview", "no plane to preview"));
        }
    };
    Ok(pixels.concat())
}

/// Grey levels for a depth plane: 255 at the nearest hit, 0 at the farthest and for misses.
fn depth_preview(depth: &Plane) -> Vec<[u8; 4]> {
    let is_hit = |d: f32| d.is_finite() && d < BACKGROUND_DEPTH;
    let (near, far) = depth
        .data
        .iter()
        .filter(|&&d| is_hit(d))
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &d| {
            (lo.min(d), hi.max(d))
        });
    let span = far - near;
    depth
        .data
        .iter()
        .map(|&d| match is_hit(d) {
            false => grey(0),
            true if span > 0.0 => grey(linear_u8(1.0 - (d - near) / span)),
            true => grey(255),
        })
        .collect()
}

/// An opaque grey pixel.
fn grey(v: u8) -> [u8; 4] {
    [v, v, v, 255]
}

/// `x` clamped to [0, 1] and rounded to 0..=255; NaN gives 0.
fn linear_u8(x: f32) -> u8 {
    // `as u8` saturates and maps NaN to 0.
    (x.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// The sRGB transfer (IEC 61966-2-1): `12.92·x` for `x ≤ 0.0031308`, else
/// `1.055·x^(1/2.4) − 0.055`.
fn srgb_encode(x: f32) -> f32 {
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// A linear value as an 8-bit sRGB code value.
fn srgb_u8(x: f32) -> u8 {
    linear_u8(srgb_encode(x.clamp(0.0, 1.0)))
}

/// A minimal PNG decoder, written independently of the encoder, for tests: checks the
/// signature and every chunk's CRC, accepts only 8-bit RGBA, non-interlaced, filter type 0.
#[cfg(test)]
pub(crate) mod png_decode {
    use std::io::Read;

    /// CRC-32 (ISO 3309, reflected polynomial 0xEDB88320), one bit at a time.
    fn crc32(bytes: &[u8]) -> u32 {
        let mut crc = 0xFFFF_FFFFu32;
        for &byte in bytes {
            crc ^= u32::from(byte);
            for _ in 0..8 {
                crc = if crc & 1 == 1 {
                    (crc >> 1) ^ 0xEDB8_8320
                } else {
                    crc >> 1
                };
            }
        }
        !crc
    }

    fn be32(b: &[u8]) -> u32 {
        u32::from_be_bytes([b[0], b[1], b[2], b[3]])
    }

    /// `(width, height, rgba)` of a PNG, panicking on anything unexpected.
    pub(crate) fn decode_rgba8(png: &[u8]) -> (u32, u32, Vec<u8>) {
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n", "signature");
        let mut at = 8;
        let mut header = None;
        let mut idat = Vec::new();
        let mut kinds = Vec::new();
        while at < png.len() {
            let len = be32(&png[at..]) as usize;
            let kind = &png[at + 4..at + 8];
            let data = &png[at + 8..at + 8 + len];
            let crc = be32(&png[at + 8 + len..]);
            assert_eq!(
                crc,
                crc32(&png[at + 4..at + 8 + len]),
                "CRC of chunk {kind:?}"
            );
            kinds.push(kind.to_vec());
            match kind {
                b"IHDR" => header = Some(data.to_vec()),
                b"IDAT" => idat.extend_from_slice(data),
                _ => {}
            }
            at += 12 + len;
        }
        assert_eq!(at, png.len(), "trailing bytes");
        assert_eq!(kinds.first().map(Vec::as_slice), Some(&b"IHDR"[..]));
        assert_eq!(kinds.last().map(Vec::as_slice), Some(&b"IEND"[..]));
        let h = header.unwrap_or_default();
        assert_eq!(h.len(), 13, "IHDR length");
        let (width, height) = (be32(&h[0..]), be32(&h[4..]));
        assert_eq!(
            &h[8..],
            &[8, 6, 0, 0, 0],
            "8-bit RGBA, deflate, no interlace"
        );

        let mut raw = Vec::new();
        flate2::read::ZlibDecoder::new(&idat[..])
            .read_to_end(&mut raw)
            .unwrap();
        let stride = 1 + 4 * width as usize;
        assert_eq!(raw.len(), stride * height as usize, "inflated size");
        let mut rgba = Vec::with_capacity(raw.len());
        for row in raw.chunks_exact(stride) {
            assert_eq!(row[0], 0, "filter type");
            rgba.extend_from_slice(&row[1..]);
        }
        (width, height, rgba)
    }

    #[test]
    fn crc32_matches_the_standard_check_value() {
        // The CRC-32 check value of the ASCII digits "123456789".
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    }
}

#[cfg(test)]
mod tests {
    use super::png_decode::decode_rgba8;
    use super::*;

    fn empty(width: u32, height: u32) -> Planes {
        Planes {
            width,
            height,
            rgb: None,
            alpha: None,
            depth_z: None,
            depth_ray: None,
            depth_median: None,
        }
    }

    fn plane(width: u32, data: Vec<f32>) -> Plane {
        Plane {
            width,
            height: data.len() as u32 / width,
            data,
        }
    }

    /// sRGB encoding written out again, in f64, rounded to 8 bits.
    fn srgb_reference(x: f64) -> u8 {
        let x = x.clamp(0.0, 1.0);
        let v = if x <= 0.0031308 {
            x * 12.92
        } else {
            1.055 * x.powf(1.0 / 2.4) - 0.055
        };
        (v * 255.0).round() as u8
    }

    #[test]
    fn srgb_transfer_at_known_points() {
        assert_eq!(srgb_u8(0.0), 0);
        assert_eq!(srgb_u8(1.0), 255);
        assert_eq!(srgb_u8(0.5), 188); // 0.7353569 · 255 = 187.52
        assert_eq!(srgb_u8(0.18), 118); // 0.4613561 · 255 = 117.65
        assert_eq!(srgb_u8(-1.0), 0);
        assert_eq!(srgb_u8(7.0), 255);
        assert_eq!(srgb_u8(f32::NAN), 0);
        // Both pieces meet at the boundary: 12.92 · 0.0031308 = 0.04044994.
        assert!((srgb_encode(0.003_130_8) - 0.040_449_94).abs() < 1e-7);
        assert!((srgb_encode(0.003_130_81) - 0.040_449_94).abs() < 1e-6);
        // Linear toe: 0.001 → 0.01292, not the 0.0433 a 2.2 gamma gives.
        assert!((srgb_encode(0.001) - 0.01292).abs() < 1e-7);
    }

    #[test]
    fn rgba_preview_decodes_to_unpremultiplied_srgb() {
        // 3×2 pixels: half-covered orange, opaque grey, empty, tiny alpha with bright colour,
        // over-range colour, opaque black.
        let alpha = [0.5, 1.0, 0.0, 0.01, 1.0, 1.0];
        let straight = [
            [1.0, 0.2, 0.0],
            [0.18, 0.18, 0.18],
            [0.0, 0.0, 0.0],
            [0.5, 0.25, 0.75],
            [4.0, 0.5, -0.1],
            [0.0, 0.0, 0.0],
        ];
        let premul = |k: usize| {
            plane(
                3,
                (0..6).map(|i| (straight[i][k] * alpha[i]) as f32).collect(),
            )
        };
        let mut planes = empty(3, 2);
        planes.rgb = Some([premul(0), premul(1), premul(2)]);
        planes.alpha = Some(plane(3, alpha.iter().map(|&a| a as f32).collect()));

        let png = encode_png_rgba8(3, 2, &preview_rgba8(&planes).unwrap()).unwrap();
        let (w, h, rgba) = decode_rgba8(&png);
        assert_eq!((w, h), (3, 2));
        for i in 0..6 {
            let want = [
                srgb_reference(straight[i][0]),
                srgb_reference(straight[i][1]),
                srgb_reference(straight[i][2]),
                (alpha[i] * 255.0).round() as u8,
            ];
            assert_eq!(rgba[4 * i..4 * i + 4], want, "pixel {i}");
        }
    }

    #[test]
    fn alpha_only_is_grey_and_depth_only_is_near_bright() {
        let mut planes = empty(2, 2);
        planes.alpha = Some(plane(2, vec![0.0, 0.25, 1.0, 0.5]));
        let rgba = preview_rgba8(&planes).unwrap();
        assert_eq!(
            rgba,
            [0, 0, 0, 255, 64, 64, 64, 255, 255, 255, 255, 255, 128, 128, 128, 255]
        );

        let mut planes = empty(4, 1);
        // Near 2, far 6: 4 is half way; a miss is black.
        planes.depth_ray = Some(plane(4, vec![2.0, 4.0, 6.0, f32::INFINITY]));
        let rgba = preview_rgba8(&planes).unwrap();
        assert_eq!(
            rgba,
            [255, 255, 255, 255, 128, 128, 128, 255, 0, 0, 0, 255, 0, 0, 0, 255]
        );
    }

    #[test]
    fn written_file_decodes_and_odd_sizes_survive() {
        let (w, h) = (37, 23);
        let mut planes = empty(w, h);
        planes.alpha = Some(plane(
            w,
            (0..w * h).map(|i| (i % 256) as f32 / 255.0).collect(),
        ));
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos())
            .unwrap_or(0);
        let path =
            std::env::temp_dir().join(format!("nerfx-png-{}-{nanos}.png", std::process::id()));
        write_png_preview(&path, &planes).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        let (dw, dh, rgba) = decode_rgba8(&bytes);
        assert_eq!((dw, dh), (w, h));
        for (i, px) in rgba.chunks_exact(4).enumerate() {
            let v = (i % 256) as u8;
            assert_eq!(px, [v, v, v, 255], "pixel {i}");
        }
    }

    #[test]
    fn refuses_empty_and_mismatched_input() {
        assert!(matches!(
            encode_png_rgba8(0, 4, &[]),
            Err(Error::Invalid { .. })
        ));
        assert!(matches!(
            encode_png_rgba8(2, 2, &[0; 15]),
            Err(Error::Invalid { .. })
        ));
        assert!(matches!(
            preview_rgba8(&empty(2, 2)),
            Err(Error::Invalid { .. })
        ));
        let dir = std::env::temp_dir().join(format!("nerfx-no-such-dir-{}", std::process::id()));
        let path = dir.join("x.png");
        let mut planes = empty(1, 1);
        planes.alpha = Some(Plane::filled(1, 1, 1.0));
        match write_png_preview(&path, &planes) {
            Err(Error::Io { path: p, .. }) => assert_eq!(p, path),
            other => panic!("expected an Io error, got {other:?}"),
        }
    }
}
