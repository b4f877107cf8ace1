//! 8-bit PNG previews of render planes, encoded with the `png` crate.

use std::io::{BufWriter, Write};
use std::path::Path;

use crate::error::{Error, Result};
use crate::image::{Plane, Planes, BACKGROUND_DEPTH};

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
    write_png_rgba8(path, planes.width, planes.height, &rgba)
}

/// Writes `rgba` (`width × height` pixels, 4 bytes each, rows top first, non-premultiplied
/// alpha, sRGB-encoded colour) to `path` as an 8-bit RGBA PNG tagged sRGB. The file is
/// replaced only once complete: a failed write leaves an existing one as it was.
///
/// Errors: [`Error::Invalid`] when a side is 0 or above 2³¹ − 1, or `rgba` has the wrong
/// length; [`Error::Io`] naming `path` when the file cannot be written.
pub fn write_png_rgba8(path: &Path, width: u32, height: u32, rgba: &[u8]) -> Result<()> {
    if width == 0 || height == 0 || width > MAX_SIDE || height > MAX_SIDE {
        return Err(Error::invalid(
            "PNG image",
            format!("size {width}×{height} is outside 1..2³¹−1"),
        ));
    }
    let expected = width as usize * 4 * height as usize;
    if rgba.len() != expected {
        return Err(Error::invalid(
            "PNG image",
            format!(
                "{} bytes of RGBA for {width}×{height} pixels (expected {expected})",
                rgba.len()
            ),
        ));
    }
    crate::output::replace_file(path, |temp| {
        let file = std::fs::File::create(temp).map_err(|e| Error::io(path, e))?;
        let mut out = BufWriter::new(file);
        let mut encoder = png::Encoder::new(&mut out, width, height);
        encoder.set_color(png::ColorType::Rgba);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        let encoding = |e: png::EncodingError| match e {
            png::EncodingError::IoError(e) => Error::io(path, e),
            e => Error::invalid("PNG image", e.to_string()),
        };
        let mut writer = encoder.write_header().map_err(encoding)?;
        writer.write_image_data(rgba).map_err(encoding)?;
        writer.finish().map_err(encoding)?;
        out.flush().map_err(|e| Error::io(path, e))
    })
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

/// `(width, height, rgba)` of a PNG decoded by the `png` crate, for tests: 8-bit RGBA only.
#[cfg(test)]
fn decode_rgba8(bytes: &[u8]) -> (u32, u32, Vec<u8>) {
    let mut reader = png::Decoder::new(std::io::Cursor::new(bytes))
        .read_info()
        .unwrap();
    let mut rgba = vec![0; reader.output_buffer_size().unwrap()];
    let frame = reader.next_frame(&mut rgba).unwrap();
    assert_eq!(
        (frame.color_type, frame.bit_depth),
        (png::ColorType::Rgba, png::BitDepth::Eight)
    );
    rgba.truncate(frame.buffer_size());
    (frame.width, frame.height, rgba)
}

#[cfg(test)]
mod tests {
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

    /// The preview of `planes` written to a file and read back by the `png` crate.
    fn write_and_decode(planes: &Planes) -> (u32, u32, Vec<u8>) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("preview.png");
        write_png_preview(&path, planes).unwrap();
        decode_rgba8(&std::fs::read(&path).unwrap())
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

        let (w, h, rgba) = write_and_decode(&planes);
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
    fn a_transparent_background_reads_back_transparent_and_tagged_srgb() {
        // A 4×3 render of one half-covered pixel on an empty background.
        let (w, h) = (4, 3);
        let mut alpha = vec![0.0; 12];
        alpha[5] = 0.5;
        let premul = |v: f32| plane(w, alpha.iter().map(|a| a * v).collect());
        let mut planes = empty(w, h);
        planes.rgb = Some([premul(1.0), premul(0.5), premul(0.0)]);
        planes.alpha = Some(plane(w, alpha.clone()));
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("preview.png");
        write_png_preview(&path, &planes).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let reader = png::Decoder::new(std::io::Cursor::new(&bytes))
            .read_info()
            .unwrap();
        assert!(reader.info().srgb.is_some(), "sRGB chunk");
        let (dw, dh, rgba) = decode_rgba8(&bytes);
        assert_eq!((dw, dh), (w, h));
        for (i, px) in rgba.chunks_exact(4).enumerate() {
            if i == 5 {
                assert_eq!(px, [255, srgb_reference(0.5), 0, 128]);
            } else {
                assert_eq!(
                    px,
                    [0, 0, 0, 0],
                    "pixel {i}: the background must stay clear"
                );
            }
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
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("matte.png");
        write_png_preview(&path, &planes).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let (dw, dh, rgba) = decode_rgba8(&bytes);
        assert_eq!((dw, dh), (w, h));
        for (i, px) in rgba.chunks_exact(4).enumerate() {
            let v = (i % 256) as u8;
            assert_eq!(px, [v, v, v, 255], "pixel {i}");
        }
    }

    #[test]
    fn refuses_empty_and_mismatched_input() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("x.png");
        assert!(matches!(
            write_png_rgba8(&out, 0, 4, &[]),
            Err(Error::Invalid { .. })
        ));
        assert!(matches!(
            write_png_rgba8(&out, 2, 2, &[0; 15]),
            Err(Error::Invalid { .. })
        ));
        assert!(!out.exists());
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
