//! SuperSplat's compressed PLY (what SuperSplat and PlayCanvas's splat-transform write as
//! `.compressed.ply`). Splats come in chunks of 256; the `chunk` element holds each chunk's
//! ranges as floats (`min_x … max_z` of the positions, `min_scale_x … max_scale_z` of the log
//! scales and, optionally, `min_r … max_b` of the colours); the `vertex` element holds four
//! `uint` words a splat, each value a fraction of its chunk's range:
//!
//! - `packed_position`, `packed_scale`: x, y, z in 11, 10, 11 bits (x highest);
//! - `packed_rotation`: the largest component's index (2 highest bits, in `w x y z` order) and
//!   the other three in 10 bits each, in order, as `(u − 0.5)·√2`; the largest is
//!   `√(1 − a² − b² − c²)`;
//! - `packed_color`: r, g, b, opacity in 8 bits each (r highest); the colour is as the viewer
//!   shows it (a fraction of the chunk's colour range when it has one), the opacity linear.
//!
//! The optional `sh` element holds the higher SH coefficients as bytes `f_rest_*` (channel
//! by channel as in the INRIA PLY), each `(n − 0.5)·8` with `n = (v + 0.5)/256`, except 0 and
//! 255, which stand for `n` = 0 and 1.

use std::path::Path;

use glam::Vec3;

use super::{dc_from_color, degree_of_rest, SplatFormat};
use crate::error::{Error, Result};
use crate::field::container::{Element, Ply, Property, Scalar};
use crate::field::splats::{SplatColor, Splats};

/// Splats a chunk.
pub(crate) const CHUNK: usize = 256;

/// The chunk properties every file has: position and log-scale ranges.
const RANGES: [&str; 12] = [
    "min_x",
    "min_y",
    "min_z",
    "max_x",
    "max_y",
    "max_z",
    "min_scale_x",
    "min_scale_y",
    "min_scale_z",
    "max_scale_x",
    "max_scale_y",
    "max_scale_z",
];

/// The optional colour ranges.
const COLOR_RANGES: [&str; 6] = ["min_r", "min_g", "min_b", "max_r", "max_g", "max_b"];

/// The largest magnitude a range may have: a position 10⁹ units out, a log scale of ±100 or
/// a colour of ±1000 is no capture.
fn absurd(name: &str, v: f32) -> bool {
    let limit = if name.contains("scale") {
        100.0
    } else if name.len() == 5 {
        1e9 // min_x … max_z
    } else {
        1e3
    };
    !v.is_finite() || v.abs() > limit
}

/// Splats from a parsed compressed PLY (`ply` has a `chunk` element).
pub(crate) fn parse(path: &Path, ply: &Ply) -> Result<Splats> {
    let (chunk, chunk_rows) = ply.rows("chunk")?;
    let (vertex, rows) = ply.rows("vertex")?;
    let prop = |el: &Element, name: &str| -> Result<Property> {
        el.property(name).cloned().ok_or_else(|| {
            Error::format(
                path,
                format!("element '{}'", el.name),
                format!("no property '{name}': not a SuperSplat compressed PLY"),
            )
        })
    };
    let ranges = RANGES
        .iter()
        .map(|n| prop(chunk, n))
        .collect::<Result<Vec<_>>>()?;
    let color_ranges = if chunk.property("min_r").is_some() {
        Some(
            COLOR_RANGES
                .iter()
                .map(|n| prop(chunk, n))
                .collect::<Result<Vec<_>>>()?,
        )
    } else {
        None
    };
    let words = [
        "packed_position",
        "packed_rotation",
        "packed_scale",
        "packed_color",
    ]
    .iter()
    .map(|n| {
        let p = prop(vertex, n)?;
        if p.kind != Scalar::U32 {
            return Err(Error::format(
                path,
                "element 'vertex'",
                format!("property '{n}' is not a 'uint': not a SuperSplat compressed PLY"),
            ));
        }
        Ok(p)
    })
    .collect::<Result<Vec<_>>>()?;

    let n = rows.len();
    let chunks = chunk_rows.len();
    if n.div_ceil(CHUNK) != chunks {
        return Err(Error::format(
            path,
            "element 'chunk'",
            format!(
                "{chunks} chunks for {n} splats; a chunk holds {CHUNK}, so expected {}",
                n.div_ceil(CHUNK)
            ),
        ));
    }
    // Every range is checked before a splat is decoded from it.
    for c in 0..chunks {
        for p in ranges.iter().chain(color_ranges.iter().flatten()) {
            let v = chunk_rows.get(c, p);
            if absurd(&p.name, v) {
                return Err(Error::format(
                    path,
                    format!("element 'chunk', chunk {c}, property '{}'", p.name),
                    format!("{v} is not a usable quantisation range"),
                ));
            }
        }
    }

    let sh = if ply.elements.iter().any(|e| e.name == "sh") {
        let (el, sh_rows) = ply.rows("sh")?;
        if sh_rows.len() != n {
            return Err(Error::format(
                path,
                "element 'sh'",
                format!("{} rows for {n} splats", sh_rows.len()),
            ));
        }
        let count = el.properties.len();
        let degree = degree_of_rest(count / 3)
            .filter(|_| count % 3 == 0)
            .ok_or_else(|| {
                Error::format(
                    path,
                    "element 'sh'",
                    format!("{count} properties; expected 9, 24 or 45 (SH degree 1 to 3)"),
                )
            })?;
        let props = (0..count)
            .map(|i| {
                let p = prop(el, &format!("f_rest_{i}"))?;
                if p.kind != Scalar::U8 {
                    return Err(Error::format(
                        path,
                        "element 'sh'",
                        format!("property 'f_rest_{i}' is not a 'uchar'"),
                    ));
                }
                Ok(p)
            })
            .collect::<Result<Vec<_>>>()?;
        Some((degree, props, sh_rows))
    } else {
        None
    };
    let degree = sh.as_ref().map_or(0, |(d, _, _)| *d);
    let color = SplatColor::Sh { degree };
    let per_channel = color.coefficients() - 1;

    let mut splats = Splats::with_capacity(n, color, SplatFormat::CompressedPly);
    splats.source.quantisation = format!(
        "chunks of {CHUNK}: positions and log scales 11/10/11 bits of the chunk's range, \
         rotations smallest-three in 10 bits, colour and opacity 8 bits{}{}",
        if color_ranges.is_some() {
            " of the chunk's colour range"
        } else {
            ""
        },
        if degree > 0 {
            format!(", SH degree {degree} in 8 bits")
        } else {
            String::new()
        }
    );
    let mut coeffs = vec![0.0f32; color.coefficients() * 3];
    let mut range = [0.0f32; 12];
    let mut colors = [0.0f32, 0.0, 0.0, 1.0, 1.0, 1.0];
    for i in 0..n {
        let c = i / CHUNK;
        if i % CHUNK == 0 {
            for (r, p) in range.iter_mut().zip(&ranges) {
                *r = chunk_rows.get(c, p);
            }
            if let Some(cr) = &color_ranges {
                for (r, p) in colors.iter_mut().zip(cr) {
                    *r = chunk_rows.get(c, p);
                }
            }
        }
        let [position, rotation, scale, rgba] = [0, 1, 2, 3].map(|k| rows.bits(i, &words[k]));
        let lerp3 = |t: Vec3, lo: usize| {
            let (a, b) = (
                Vec3::new(range[lo], range[lo + 1], range[lo + 2]),
                Vec3::new(range[lo + 3], range[lo + 4], range[lo + 5]),
            );
            a * (Vec3::ONE - t) + b * t
        };
        let mean = lerp3(unpack_11_10_11(position), 0);
        let log_scale = lerp3(unpack_11_10_11(scale), 6);
        let byte = |shift: u32| ((rgba >> shift) & 0xff) as f32 / 255.0;
        for ch in 0..3 {
            let t = byte(24 - 8 * ch as u32);
            let value = colors[ch] * (1.0 - t) + colors[ch + 3] * t;
            coeffs[ch] = dc_from_color(value);
        }
        let opacity = byte(0);
        if let Some((_, props, sh_rows)) = &sh {
            for ch in 0..3 {
                for k in 0..per_channel {
                    let v = sh_rows.bits(i, &props[ch * per_channel + k]);
                    coeffs[(k + 1) * 3 + ch] = sh_from_byte(v as u8);
                }
            }
        }
        if !splats.push_activated(
            mean,
            log_scale.exp(),
            unpack_rotation(rotation),
            opacity,
            &coeffs,
        ) {
            splats.dropped += 1;
        }
    }
    Ok(splats)
}

/// Three fractions from 11, 10 and 11 bits (x in the highest).
fn unpack_11_10_11(v: u32) -> Vec3 {
    Vec3::new(
        ((v >> 21) & 0x7ff) as f32 / 2047.0,
        ((v >> 11) & 0x3ff) as f32 / 1023.0,
        (v & 0x7ff) as f32 / 2047.0,
    )
}

/// A smallest-three rotation, `w x y z`.
fn unpack_rotation(v: u32) -> [f32; 4] {
    let norm = std::f32::consts::SQRT_2;
    let part = |shift: u32| (((v >> shift) & 0x3ff) as f32 / 1023.0 - 0.5) * norm;
    let (a, b, c) = (part(20), part(10), part(0));
    let m = (1.0 - (a * a + b * b + c * c)).max(0.0).sqrt();
    match v >> 30 {
        0 => [m, a, b, c],
        1 => [a, m, b, c],
        2 => [a, b, m, c],
        _ => [a, b, c, m],
    }
}

/// A higher SH coefficient from its byte.
fn sh_from_byte(v: u8) -> f32 {
    let n = match v {
        0 => 0.0,
        255 => 1.0,
        v => (f32::from(v) + 0.5) / 256.0,
    };
    (n - 0.5) * 8.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packed_words_unpack_in_their_bit_order() {
        let v = (2047 << 21) | (512 << 11);
        let t = unpack_11_10_11(v);
        assert_eq!(t.x, 1.0);
        assert!((t.y - 512.0 / 1023.0).abs() < 1e-7);
        assert_eq!(t.z, 0.0);
        // Largest w (index 0), the others 0: (u − 0.5)·√2 = 0 needs u = 0.5, which 10 bits
        // cannot hold exactly; 511.5 would, so 512 gives a small positive part.
        let q = unpack_rotation((512 << 20) | (512 << 10) | 512);
        assert!(q[0] > 0.999 && q[1].abs() < 2e-3, "{q:?}");
        let q = unpack_rotation((3 << 30) | (512 << 20) | (512 << 10) | 512);
        assert!(q[3] > 0.999, "{q:?}");
        assert_eq!(sh_from_byte(0), -4.0);
        assert_eq!(sh_from_byte(255), 4.0);
        assert_eq!(sh_from_byte(127), (127.5 / 256.0 - 0.5) * 8.0);
    }
}
