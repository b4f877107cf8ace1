//! A shot between its frames: the camera and objects at a fractional frame, for hosts that
//! render sub-frames (motion-blur samples, the second field of interlaced footage at
//! `t + 0.5`).
//!
//! At shot time `t` with `a = ⌊t⌋`, `b = a + 1` and `u = t − a`, each matrix `M = [A | c]`
//! of frames `a` and `b` is split into its translation `c` and the polar decomposition
//! `A = R·P` (`R` a rotation, `P = Rᵀ·A` symmetric: the scale, non-uniform or sheared as it
//! may be; for a mirrored matrix `P` is negative definite). Then
//! `c(u) = c_a + (c_b − c_a)·u`, `R(u) = slerp(q_a, q_b, u)` (the shorter arc) and
//! `P(u) = P_a + (P_b − P_a)·u`, so a non-uniform scale held by both frames is kept exactly
//! while the object turns. The camera's lens, sensor, shift and clipping are linear in `u`;
//! so are its depth of field's focus distance, f-stop, rotation and ratio; its type, sensor
//! fit, stereo mode and aperture blades are frame `a`'s. A whole `t` returns frame `t`
//! itself, bit for bit.

use glam::{DMat3, DMat4, DQuat};

use super::shot::{Shot, ShotCamera, ShotFrame};
use crate::error::{Error, Result};

impl Shot {
    /// The frame at shot time `time`, which may fall between two frames (see the module
    /// documentation). A whole `time` is [`Shot::frame`]'s frame unchanged; a fractional one
    /// needs both neighbouring frames in the shot, and the result carries the earlier
    /// frame's number. Times outside the shot, or not finite, are refused naming the file.
    pub fn frame_at(&self, time: f64) -> Result<ShotFrame> {
        if !time.is_finite() || time.abs() >= 9.0e15 {
            return Err(Error::format(
                &self.source,
                "frames",
                format!("time {time} is not a frame"),
            ));
        }
        let a = time.floor();
        let u = time - a;
        let first = self.frame(a as i64)?;
        if u == 0.0 {
            return Ok(first.clone());
        }
        let second = self.frame(a as i64 + 1)?;
        Ok(between(first, second, u))
    }
}

/// Frames `a` and `b` mixed at `u` in (0, 1).
fn between(a: &ShotFrame, b: &ShotFrame, u: f64) -> ShotFrame {
    let lerp = |x: f64, y: f64| x + (y - x) * u;
    let (ca, cb) = (&a.camera, &b.camera);
    let camera = ShotCamera {
        world_from_camera: mix_matrix(ca.world_from_camera, cb.world_from_camera, u),
        kind: ca.kind,
        lens: lerp(ca.lens, cb.lens),
        sensor_width: lerp(ca.sensor_width, cb.sensor_width),
        sensor_height: lerp(ca.sensor_height, cb.sensor_height),
        sensor_fit: ca.sensor_fit,
        shift_x: lerp(ca.shift_x, cb.shift_x),
        shift_y: lerp(ca.shift_y, cb.shift_y),
        clip_start: lerp(ca.clip_start, cb.clip_start),
        clip_end: lerp(ca.clip_end, cb.clip_end),
        stereo: ca.stereo.map(|s| match cb.stereo {
            Some(t) if t.mode == s.mode => super::ShotStereo {
                ipd: lerp(s.ipd, t.ipd),
                ..s
            },
            _ => s,
        }),
        dof: ca.dof.map(|d| match cb.dof {
            Some(e) => super::DepthOfField {
                focus_distance: lerp(d.focus_distance, e.focus_distance),
                fstop: lerp(d.fstop, e.fstop),
                rotation: lerp(d.rotation, e.rotation),
                ratio: lerp(d.ratio, e.ratio),
                ..d
            },
            None => d,
        }),
    };
    // Objects held by both frames (one appearing or vanishing between them is absent).
    let objects = a
        .objects
        .iter()
        .filter_map(|(name, ma)| {
            let mb = b.objects.get(name)?;
            Some((name.clone(), mix_matrix(*ma, *mb, u)))
        })
        .collect();
    ShotFrame {
        frame: a.frame,
        camera,
        objects,
    }
}

/// `a` and `b` mixed at `u`: translation and the polar stretch linearly, the rotation by
/// slerp.
pub(crate) fn mix_matrix(a: DMat4, b: DMat4, u: f64) -> DMat4 {
    let (ra, pa) = polar(DMat3::from_mat4(a));
    let (rb, pb) = polar(DMat3::from_mat4(b));
    let qa = DQuat::from_mat3(&ra).normalize();
    let qb = DQuat::from_mat3(&rb).normalize();
    let r = DMat3::from_quat(qa.slerp(qb, u).normalize());
    let p = pa + (pb - pa) * u;
    let m = r * p;
    let c = a.w_axis + (b.w_axis - a.w_axis) * u;
    DMat4::from_cols(
        m.x_axis.extend(0.0),
        m.y_axis.extend(0.0),
        m.z_axis.extend(0.0),
        c,
    )
}

/// The polar decomposition `A = R·P` with `R` a proper rotation and `P = Rᵀ·A` symmetric,
/// by Newton's iteration `Q ← (Q + Q⁻ᵀ)/2` (quadratic convergence from `Q = ±A`), the sign
/// chosen so that `det Q = +1`. `A` must be invertible (shot matrices are checked).
fn polar(a: DMat3) -> (DMat3, DMat3) {
    let mut q = if a.determinant() < 0.0 { -a } else { a };
    for _ in 0..100 {
        let next = (q + q.inverse().transpose()) * 0.5;
        let change = (next - q)
            .to_cols_array()
            .iter()
            .map(|v| v.abs())
            .sum::<f64>();
        q = next;
        // Newton converges quadratically to a rotation, whose entries are at most 1, so an
        // absolute tolerance works for any scale of `a`; 1e-13 sits above the rounding noise
        // of the nine entries (a few ulps each), which 1e-15 did not, running all 100 steps.
        if change <= 1e-13 {
            break;
        }
    }
    (q, q.transpose() * a)
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use glam::DVec3;

    use super::*;
    use crate::camera::{SensorFit, ShotCameraKind};

    /// Columns written out: `R_z(angle)` times `diag(sx, sy, sz)`, then translation `t`.
    fn rz_scaled(angle: f64, s: [f64; 3], t: [f64; 3]) -> DMat4 {
        let (sn, cs) = angle.sin_cos();
        DMat4::from_cols_array(&[
            cs * s[0],
            sn * s[0],
            0.0,
            0.0,
            -sn * s[1],
            cs * s[1],
            0.0,
            0.0,
            0.0,
            0.0,
            s[2],
            0.0,
            t[0],
            t[1],
            t[2],
            1.0,
        ])
    }

    fn camera(world_from_camera: DMat4, lens: f64, shift_x: f64) -> ShotCamera {
        ShotCamera {
            world_from_camera,
            kind: ShotCameraKind::Perspective,
            lens,
            sensor_width: 36.0,
            sensor_height: 24.0,
            sensor_fit: SensorFit::Auto,
            shift_x,
            shift_y: 0.0,
            clip_start: 0.1,
            clip_end: 100.0,
            stereo: None,
            dof: None,
        }
    }

    /// Frames 10 and 11: the camera turns about Z from 0.2 to 1.0 rad and moves from
    /// (1, 2, 3) to (3, 6, −1), the lens goes 35 → 50 mm; the object keeps the scale (1, 2, 3)
    /// while it turns from 0 to 0.8 rad.
    fn shot() -> Shot {
        let frame = |n: i64, cam: DMat4, lens: f64, obj: DMat4| ShotFrame {
            frame: n,
            camera: camera(cam, lens, 0.1 * n as f64),
            objects: BTreeMap::from([("NeRF".to_string(), obj)]),
        };
        Shot {
            fps: 24.0,
            fps_base: 1.0,
            resolution_x: 64,
            resolution_y: 32,
            resolution_percentage: 100,
            pixel_aspect_x: 1.0,
            pixel_aspect_y: 1.0,
            nerf_object: "NeRF".into(),
            motion_blur: None,
            scene_world: crate::camera::SceneWorld::Blender,
            frames: vec![
                frame(
                    10,
                    rz_scaled(0.2, [1.0; 3], [1.0, 2.0, 3.0]),
                    35.0,
                    rz_scaled(0.0, [1.0, 2.0, 3.0], [0.0; 3]),
                ),
                frame(
                    11,
                    rz_scaled(1.0, [1.0; 3], [3.0, 6.0, -1.0]),
                    50.0,
                    rz_scaled(0.8, [1.0, 2.0, 3.0], [0.0; 3]),
                ),
            ],
            source: "shot.json".into(),
        }
    }

    fn close(a: DMat4, b: DMat4) -> bool {
        a.abs_diff_eq(b, 1e-12)
    }

    #[test]
    fn whole_frames_are_the_frames_themselves() {
        let s = shot();
        assert_eq!(s.frame_at(10.0).unwrap(), s.frames[0]);
        assert_eq!(s.frame_at(11.0).unwrap(), s.frames[1]);
    }

    #[test]
    fn halfway_turns_by_half_the_angle_and_moves_to_the_midpoint() {
        let f = shot().frame_at(10.5).unwrap();
        assert_eq!(f.frame, 10);
        let want = rz_scaled(0.6, [1.0; 3], [2.0, 4.0, 1.0]);
        assert!(close(f.camera.world_from_camera, want), "{f:?}");
        assert!((f.camera.lens - 42.5).abs() < 1e-12);
        assert!((f.camera.shift_x - 1.05).abs() < 1e-12);
        assert_eq!(f.camera.sensor_width, 36.0);
        // The non-uniform scale (1, 2, 3) is kept while the object turns.
        let obj = f.object_matrix("NeRF").unwrap();
        assert!(
            close(obj, rz_scaled(0.4, [1.0, 2.0, 3.0], [0.0; 3])),
            "{obj}"
        );
        // A quarter of the way.
        let f = shot().frame_at(10.25).unwrap();
        let want = rz_scaled(0.4, [1.0; 3], [1.5, 3.0, 2.0]);
        assert!(close(f.camera.world_from_camera, want));
        assert!((f.camera.lens - 38.75).abs() < 1e-12);
    }

    #[test]
    fn a_sheared_or_mirrored_matrix_keeps_its_stretch() {
        // A = R_x(θ)·S with S symmetric, not diagonal: S stays, R_x turns 0 → 0.8.
        let s = DMat3::from_cols_array(&[2.0, 0.5, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0, 1.0]);
        let rx = |t: f64| {
            let (sn, cs) = t.sin_cos();
            DMat3::from_cols_array(&[1.0, 0.0, 0.0, 0.0, cs, sn, 0.0, -sn, cs])
        };
        let m = |t: f64| DMat4::from_mat3(rx(t) * s);
        assert!(close(mix_matrix(m(0.0), m(0.8), 0.25), m(0.2)));
        // A mirror (scale −1 in x) turning about Z 0 → 0.4.
        let mirrored = |t: f64| rz_scaled(t, [-1.0, 1.0, 1.0], [0.0; 3]);
        let got = mix_matrix(mirrored(0.0), mirrored(0.4), 0.5);
        assert!(close(got, mirrored(0.2)), "{got}");
    }

    #[test]
    fn times_outside_the_shot_are_refused() {
        let s = shot();
        for t in [9.5, 11.5, 12.0, f64::NAN, f64::INFINITY] {
            let e = s.frame_at(t).unwrap_err().to_string();
            assert!(e.contains("shot.json"), "{t}: {e}");
        }
        // The translation is exactly linear: at 10.75 the camera is 3/4 of the way.
        let f = s.frame_at(10.75).unwrap();
        let c = f.camera.world_from_camera.w_axis.truncate();
        assert!((c - DVec3::new(2.5, 5.0, 0.0)).length() < 1e-12);
    }
}
