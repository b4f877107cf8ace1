//! Splats from an INRIA-layout PLY (what 3DGS, gsplat's examples, Postshot and
//! `ns-export gaussian-splat` write): `x y z`, `f_dc_0..2`, `f_rest_*` (each channel's
//! higher coefficients in turn: red's, then green's, then blue's), `opacity` (logit),
//! `scale_0..2` (log), `rot_0..3` (`w x y z`, unnormalised). Other properties are ignored.
//! A PLY with a `chunk` element is SuperSplat's compressed layout, read by
//! [`compressed_ply`](super::formats::compressed_ply).

use std::path::Path;

use glam::{Quat, Vec3};

use super::formats::{antialiased_from_comments, compressed_ply, SplatFormat};
use super::{SplatColor, Splats};
use crate::error::{Error, Result};
use crate::field::container::{Ply, Property};

/// Reads a splat PLY file whole (a regular file, up to its real size).
pub(super) fn read(path: &Path) -> Result<Splats> {
    let bytes = crate::input::read_bytes(path)?;
    parse(path, &bytes)
}

/// Splats from the bytes of a PLY file (`path` for messages).
pub(super) fn parse(path: &Path, bytes: &[u8]) -> Result<Splats> {
    let ply = Ply::parse(path, bytes)?;
    let antialiased = antialiased_from_comments(&ply.comments);
    if ply.elements.iter().any(|e| e.name == "chunk") {
        let mut splats = compressed_ply::parse(path, &ply)?;
        splats.source.antialiased = antialiased;
        return Ok(splats);
    }
    let (vertex, rows) = ply.rows("vertex")?;
    let prop = |name: &str| {
        vertex.property(name).ok_or_else(|| {
            Error::format(
                path,
                "element 'vertex'",
                format!("no property '{name}': not a Gaussian-splat PLY (3DGS layout)"),
            )
        })
    };
    let props = |names: &[&str]| names.iter().map(|n| prop(n)).collect::<Result<Vec<_>>>();
    let position = props(&["x", "y", "z"])?;
    let dc = props(&["f_dc_0", "f_dc_1", "f_dc_2"])?;
    let opacity = prop("opacity")?;
    let scale = props(&["scale_0", "scale_1", "scale_2"])?;
    let rot = props(&["rot_0", "rot_1", "rot_2", "rot_3"])?;
    let rest_count = vertex
        .properties
        .iter()
        .filter(|p| p.name.starts_with("f_rest_"))
        .count();
    let degree = match rest_count {
        0 => 0,
        9 => 1,
        24 => 2,
        45 => 3,
        n => {
            return Err(Error::format(
                path,
                "element 'vertex'",
                format!("{n} f_rest_* properties; expected 0, 9, 24 or 45 (SH degree 0 to 3)"),
            ))
        }
    };
    let rest = (0..rest_count)
        .map(|i| prop(&format!("f_rest_{i}")))
        .collect::<Result<Vec<_>>>()?;
    let per_channel = rest_count / 3;
    let color = SplatColor::Sh { degree };
    let coefficients = color.coefficients();

    let n = rows.len();
    let mut splats = Splats::with_capacity(n, color, SplatFormat::InriaPly);
    splats.source.antialiased = antialiased;
    splats.source.quantisation = "none: 32-bit floats".into();
    let vec3 = |row: usize, p: &[&Property]| {
        Vec3::new(
            rows.get(row, p[0]),
            rows.get(row, p[1]),
            rows.get(row, p[2]),
        )
    };
    let mut coeffs = vec![0.0f32; coefficients * 3];
    for row in 0..n {
        let mean = vec3(row, &position);
        let log_scale = vec3(row, &scale);
        let logit = rows.get(row, opacity);
        let q = [0, 1, 2, 3].map(|i| rows.get(row, rot[i]));
        for c in 0..3 {
            coeffs[c] = rows.get(row, dc[c]);
            for k in 0..per_channel {
                coeffs[(k + 1) * 3 + c] = rows.get(row, rest[c * per_channel + k]);
            }
        }
        if !splats.push(mean, log_scale, q, logit, &coeffs) {
            splats.dropped += 1;
        }
    }
    Ok(splats)
}

impl Splats {
    /// Writes the splats as an INRIA-layout binary PLY (`x y z`, `f_dc_*`, `f_rest_*`,
    /// `opacity` as a logit, `scale_*` as logs, `rot_*` as `w x y z`), what the readers of
    /// 3DGS tools take. Sigmoid-coloured splats are written as degree 0 with the coefficient
    /// that gives the same colour.
    pub fn write_ply(&self, path: &Path) -> Result<()> {
        let rest = match self.color {
            SplatColor::Sh { degree } => (usize::from(degree) + 1).pow(2) - 1,
            SplatColor::Sigmoid => 0,
        };
        let mut header = format!(
            "ply\nformat binary_little_endian 1.0\nelement vertex {}\n",
            self.len()
        );
        let mut names: Vec<String> = ["x", "y", "z"].map(String::from).to_vec();
        names.extend((0..3).map(|c| format!("f_dc_{c}")));
        names.extend((0..3 * rest).map(|k| format!("f_rest_{k}")));
        names.push("opacity".into());
        names.extend((0..3).map(|c| format!("scale_{c}")));
        names.extend((0..4).map(|c| format!("rot_{c}")));
        for n in &names {
            header.push_str(&format!("property float {n}\n"));
        }
        header.push_str("end_header\n");
        let n = self.color.coefficients() * 3;
        let mut out = header.into_bytes();
        out.reserve(self.len() * names.len() * 4);
        let mut put = |v: f32| out.extend_from_slice(&v.to_le_bytes());
        for i in 0..self.len() {
            for v in self.means[i].to_array() {
                put(v);
            }
            let k = &self.coefficients[i * n..(i + 1) * n];
            for &dc in &k[..3] {
                put(match self.color {
                    // sigmoid(c) = 0.5 + Y₀·k: the SH coefficient of the same colour.
                    SplatColor::Sigmoid => (1.0 / (1.0 + (-dc).exp()) - 0.5) / 0.282_094_8,
                    SplatColor::Sh { .. } => dc,
                });
            }
            for c in 0..3 {
                for j in 0..rest {
                    put(k[(j + 1) * 3 + c]);
                }
            }
            let o = self.opacities[i];
            put((o / (1.0 - o)).ln());
            for v in self.scales[i].to_array() {
                put(v.ln());
            }
            let q = self.rotations[i];
            for v in [q.w, q.x, q.y, q.z] {
                put(v);
            }
        }
        crate::output::write_file(path, &out)
    }

    /// Activates and appends one splat as stored (log scales, `w x y z` quaternion, opacity
    /// logit, coefficient-major colour); `false` (nothing appended) when a value is not finite
    /// or the quaternion is zero. An infinite logit is the opacity 0 or 1 it stands for (what
    /// tools write for a quantised opacity of 0 or 255).
    pub(super) fn push(
        &mut self,
        mean: Vec3,
        log_scale: Vec3,
        wxyz: [f32; 4],
        logit: f32,
        coefficients: &[f32],
    ) -> bool {
        if logit.is_nan() {
            return false;
        }
        let opacity = 1.0 / (1.0 + (-logit).exp());
        self.push_activated(mean, log_scale.exp(), wxyz, opacity, coefficients)
    }

    /// Appends one splat given with linear scales and an opacity in [0, 1] (the quaternion
    /// `w x y z`, normalised here); `false` (nothing appended) when a value is not finite, the
    /// opacity is outside [0, 1] or the quaternion is zero.
    pub fn push_activated(
        &mut self,
        mean: Vec3,
        scale: Vec3,
        wxyz: [f32; 4],
        opacity: f32,
        coefficients: &[f32],
    ) -> bool {
        let [w, x, y, z] = wxyz;
        let q = Quat::from_xyzw(x, y, z, w);
        let length = q.length();
        let finite = mean.is_finite()
            && scale.is_finite()
            && length.is_finite()
            && length > 0.0
            && (0.0..=1.0).contains(&opacity)
            && coefficients.iter().all(|c| c.is_finite());
        if !finite {
            return false;
        }
        self.means.push(mean);
        self.scales.push(scale);
        self.rotations.push(q / length);
        self.opacities.push(opacity);
        self.coefficients.extend_from_slice(coefficients);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A PLY in the 3DGS layout with the given rows of
    /// `x y z nx ny nz f_dc(3) f_rest(45) opacity scale(3) rot(4)`.
    pub(crate) fn inria_ply(rows: &[[f32; 62]]) -> Vec<u8> {
        let mut h = format!(
            "ply\nformat binary_little_endian 1.0\nelement vertex {}\n",
            rows.len()
        );
        let mut names: Vec<String> = ["x", "y", "z", "nx", "ny", "nz"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        names.extend((0..3).map(|i| format!("f_dc_{i}")));
        names.extend((0..45).map(|i| format!("f_rest_{i}")));
        names.push("opacity".into());
        names.extend((0..3).map(|i| format!("scale_{i}")));
        names.extend((0..4).map(|i| format!("rot_{i}")));
        for n in &names {
            h.push_str(&format!("property float {n}\n"));
        }
        h.push_str("end_header\n");
        let mut v = h.into_bytes();
        for r in rows {
            for x in r {
                v.extend_from_slice(&x.to_le_bytes());
            }
        }
        v
    }

    fn row(i: f32) -> [f32; 62] {
        let mut r = [0.0f32; 62];
        for (k, x) in r.iter_mut().enumerate() {
            *x = i + k as f32 * 0.01;
        }
        r[54] = 0.0; // opacity logit → 0.5
        r[55..58].copy_from_slice(&[0.0, 1.0, -1.0]); // log scales
        r[58..62].copy_from_slice(&[2.0, 0.0, 0.0, 0.0]); // w = 2: identity after normalising
        r
    }

    #[test]
    fn activates_and_reorders_channel_major_rest_coefficients() {
        let bytes = inria_ply(&[row(1.0)]);
        let s = parse(Path::new("t.ply"), &bytes).unwrap();
        assert_eq!(s.len(), 1);
        assert_eq!(s.color, SplatColor::Sh { degree: 3 });
        assert_eq!(s.opacities[0], 0.5);
        assert_eq!(s.scales[0], Vec3::new(1.0, 1f32.exp(), (-1f32).exp()));
        assert_eq!(s.rotations[0], Quat::IDENTITY);
        let r = row(1.0);
        // Coefficient k of channel c: DC is f_dc_c; k ≥ 1 is f_rest_{c·15 + k − 1}.
        for k in 0..16 {
            for c in 0..3 {
                let want = if k == 0 {
                    r[6 + c]
                } else {
                    r[9 + c * 15 + k - 1]
                };
                assert_eq!(s.coefficients[k * 3 + c], want, "k {k} c {c}");
            }
        }
    }

    #[test]
    fn written_splats_read_back_the_same() {
        let bytes = inria_ply(&[row(1.0), row(2.5)]);
        let s = parse(Path::new("t.ply"), &bytes).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("back.ply");
        s.write_ply(&path).unwrap();
        let back = read(&path).unwrap();
        assert_eq!(back.color, s.color);
        assert_eq!(back.means, s.means);
        assert_eq!(back.coefficients, s.coefficients);
        for (a, b) in back.scales.iter().zip(&s.scales) {
            assert!((*a - *b).abs().max_element() <= 1e-6 * b.max_element());
        }
        for (a, b) in back.opacities.iter().zip(&s.opacities) {
            assert!((a - b).abs() <= 1e-6);
        }
        assert!(back
            .rotations
            .iter()
            .zip(&s.rotations)
            .all(|(a, b)| a.abs_diff_eq(*b, 1e-6)));
    }

    #[test]
    fn non_finite_and_zero_rotation_splats_are_dropped_and_counted() {
        let mut nan = row(2.0);
        nan[20] = f32::NAN;
        let mut zero_q = row(3.0);
        zero_q[58] = 0.0;
        let mut inf_scale = row(4.0);
        inf_scale[56] = f32::INFINITY;
        let bytes = inria_ply(&[row(1.0), nan, zero_q, inf_scale, row(5.0)]);
        let s = parse(Path::new("t.ply"), &bytes).unwrap();
        assert_eq!((s.len(), s.dropped), (2, 3));
        assert_eq!(s.means[1].x, 5.0);
    }

    #[test]
    fn missing_properties_and_odd_rest_counts_are_named() {
        let bytes = inria_ply(&[row(1.0)]);
        let text = String::from_utf8_lossy(&bytes).replacen(
            "property float opacity",
            "property float alpha",
            1,
        );
        let mut broken = text.as_bytes()[..text.find("end_header\n").unwrap() + 11].to_vec();
        broken.extend_from_slice(&bytes[broken.len()..]);
        let e = parse(Path::new("scan.ply"), &broken)
            .unwrap_err()
            .to_string();
        assert!(e.contains("scan.ply") && e.contains("'opacity'"), "{e}");

        let text = String::from_utf8_lossy(&bytes).replacen("property float f_rest_44\n", "", 1);
        let e = parse(Path::new("scan.ply"), text.as_bytes())
            .unwrap_err()
            .to_string();
        assert!(e.contains("44 f_rest_"), "{e}");
    }

    #[test]
    fn mutated_files_give_splats_or_errors_never_a_panic() {
        let good = inria_ply(&[row(1.0), row(2.0), row(3.0)]);
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for _ in 0..3000 {
            let mut bytes = good.clone();
            match next() % 4 {
                0 => bytes.truncate((next() as usize) % good.len()),
                1 => {
                    for _ in 0..1 + next() % 8 {
                        let at = next() as usize % bytes.len();
                        bytes[at] ^= 1 << (next() % 8);
                    }
                }
                2 => {
                    let at = next() as usize % bytes.len();
                    let digit = b'0' + (next() % 10) as u8;
                    bytes.insert(at, digit);
                }
                _ => {
                    let at = next() as usize % bytes.len();
                    bytes[at..].iter_mut().take(4).for_each(|b| *b = 0xff);
                }
            }
            if let Ok(s) = parse(Path::new("fuzz.ply"), &bytes) {
                assert!(s.means.iter().all(|m| m.is_finite()));
                assert!(s.opacities.iter().all(|o| (0.0..=1.0).contains(o)));
            }
        }
    }
}
