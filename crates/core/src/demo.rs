//! The embedded demo: an analytic object inside an analytic environment, seen by a Blender
//! camera. It needs no downloads, and it is also the benchmark's scene.
//!
//! The world is Blender's (Z up). The environment is a ground slab, two pillars, a back wall
//! whose colour changes with the view direction, and a wisp of Gaussian haze; the object (bound to
//! the shot's `NeRF` object, rotated and non-uniformly scaled) is a glossy sphere, a
//! semi-transparent cube and a glowing blob. As one scene ([`scene_desc`]) both are marched
//! jointly, so the haze sits in front of and behind the object correctly; `nerfx demo` shows
//! them as a compositor puts them together (the graph crate's demo comp): each rendered apart, a shadow
//! caught on the environment, the object merged in by depth.

use std::collections::BTreeMap;
use std::path::PathBuf;

use glam::{DMat4, DQuat, DVec3, Vec3};

use crate::camera::{
    BlenderIntrinsics, Camera, Perspective, Projection, SceneWorld, SensorFit, Shot, ShotCamera,
    ShotCameraKind, ShotFrame,
};
use crate::error::Result;
use crate::field::{Analytic, Primitive, ShColor, Shape};
use crate::scene::{FieldSource, InstanceDesc, Scene, SceneDesc};

/// The shot object the demo's object instance is bound to.
pub const NERF_OBJECT: &str = "NeRF";

/// The demo's first frame.
pub const FIRST_FRAME: i64 = 1001;

/// Frames in the demo shot.
pub const FRAMES: i64 = 24;

/// The camera's clipping range (Blender's `clip_start`, `clip_end`).
const CLIP: [f64; 2] = [0.1, 1000.0];

fn prim(shape: Shape, density: f32, color: ShColor) -> Primitive {
    Primitive {
        shape,
        density,
        color,
    }
}

/// A view-dependent colour from constant, known-good coefficients.
fn sh(k: &[Vec3]) -> ShColor {
    ShColor::from_coefficients(k).expect("the demo's SH coefficients are 4 finite triples")
}

fn rgb(r: f32, g: f32, b: f32) -> ShColor {
    ShColor::constant(Vec3::new(r, g, b))
}

/// The environment: ground, pillars, a view-dependent wall, haze.
fn environment() -> Analytic {
    let pillar = |x: f32, y: f32| Shape::Box {
        min: Vec3::new(x - 0.3, y - 0.3, 0.0),
        max: Vec3::new(x + 0.3, y + 0.3, 3.0),
    };
    // Degree-1 SH: bluer seen from the left (+x direction of travel), warmer from the right.
    let wall_color = sh(&[
        Vec3::new(1.4, 1.5, 1.7),
        Vec3::ZERO,
        Vec3::new(0.0, 0.1, 0.2),
        Vec3::new(0.3, 0.0, -0.3),
    ]);
    Analytic {
        primitives: vec![
            prim(
                Shape::Box {
                    min: Vec3::new(-8.0, -8.0, -0.5),
                    max: Vec3::new(8.0, 8.0, 0.0),
                },
                40.0,
                rgb(0.30, 0.28, 0.25),
            ),
            prim(pillar(-3.0, 2.5), 30.0, rgb(0.60, 0.52, 0.45)),
            prim(pillar(3.0, 3.5), 30.0, rgb(0.45, 0.50, 0.60)),
            prim(
                Shape::Box {
                    min: Vec3::new(-8.0, 6.0, 0.0),
                    max: Vec3::new(8.0, 6.5, 5.0),
                },
                50.0,
                wall_color,
            ),
            prim(
                Shape::Gaussian {
                    center: Vec3::new(-2.2, 1.2, 0.6),
                    sigma: 0.45,
                    cutoff: 4.0,
                },
                1.5,
                rgb(0.55, 0.65, 0.85),
            ),
        ],
    }
}

/// The object: glossy sphere, glassy cube, glowing blob (field units, centred at 0).
fn object() -> Analytic {
    let glossy = sh(&[
        Vec3::new(2.4, 0.9, 0.6),
        Vec3::new(0.0, 0.3, 0.3),
        Vec3::new(0.5, 0.2, 0.1),
        Vec3::new(-0.4, 0.0, 0.2),
    ]);
    Analytic {
        primitives: vec![
            prim(
                Shape::Sphere {
                    center: Vec3::new(-0.3, 0.0, 0.0),
                    radius: 0.7,
                },
                25.0,
                glossy,
            ),
            prim(
                Shape::Box {
                    min: Vec3::new(0.2, -0.9, -0.5),
                    max: Vec3::new(1.2, 0.1, 0.5),
                },
                1.5,
                rgb(0.2, 0.45, 0.9),
            ),
            prim(
                Shape::Gaussian {
                    center: Vec3::new(0.6, 0.6, 0.6),
                    sigma: 0.25,
                    cutoff: 4.0,
                },
                12.0,
                rgb(1.6, 1.2, 0.4),
            ),
        ],
    }
}

/// The demo scene file: the environment fixed, the object bound to [`NERF_OBJECT`].
pub fn scene_desc() -> SceneDesc {
    SceneDesc {
        instances: vec![
            InstanceDesc {
                name: "environment".into(),
                field: FieldSource::Analytic(environment()),
                world_from_field: None,
                object: None,
                crop: None,
            },
            InstanceDesc {
                name: "object".into(),
                field: FieldSource::Analytic(object()),
                world_from_field: None,
                object: Some(NERF_OBJECT.into()),
                crop: None,
            },
        ],
        colorspace: None,
    }
}

/// The shadow the object would cast on the ground, as a field: a Gaussian flattened onto the
/// ground under it, rendered as an accumulation pass it stands in for a Blender
/// shadow-catcher render in the demo graph (the catcher's alpha is the shadow).
pub fn shadow_desc() -> SceneDesc {
    let flatten = DMat4::from_scale_rotation_translation(
        DVec3::new(1.3, 1.1, 0.05),
        DQuat::IDENTITY,
        DVec3::new(0.2, 0.3, 0.0),
    );
    SceneDesc {
        instances: vec![InstanceDesc {
            name: "shadow".into(),
            field: FieldSource::Analytic(Analytic {
                primitives: vec![prim(
                    Shape::Gaussian {
                        center: Vec3::ZERO,
                        sigma: 0.6,
                        cutoff: 3.0,
                    },
                    6.0,
                    rgb(0.0, 0.0, 0.0),
                )],
            }),
            world_from_field: Some(flatten.transpose().to_cols_array_2d()),
            object: None,
            crop: None,
        }],
        colorspace: None,
    }
}

/// The NeRF object's `matrix_world` at `frame`: lifted, turning slowly, non-uniformly scaled.
pub(crate) fn object_matrix(frame: i64) -> DMat4 {
    let turn = 0.5 + 0.05 * (frame - FIRST_FRAME) as f64;
    DMat4::from_scale_rotation_translation(
        DVec3::new(1.2, 1.0, 0.8),
        DQuat::from_rotation_z(turn),
        DVec3::new(0.0, 0.0, 1.0),
    )
}

/// A camera at `eye` looking at `target`, Z up (Blender's `matrix_world` convention: the
/// camera looks down its −Z with +Y up). Looking straight up or down, +Y is "up" instead.
pub fn look_at(eye: DVec3, target: DVec3) -> DMat4 {
    let forward = (target - eye).normalize();
    let up = if forward.cross(DVec3::Z).length_squared() > 1e-12 {
        DVec3::Z
    } else {
        DVec3::Y
    };
    let right = forward.cross(up).normalize();
    let up = right.cross(forward);
    DMat4::from_cols(
        right.extend(0.0),
        up.extend(0.0),
        (-forward).extend(0.0),
        eye.extend(1.0),
    )
}

/// The camera's `matrix_world` at `frame`: a slow orbit.
pub(crate) fn camera_matrix(frame: i64) -> DMat4 {
    let angle = -0.8 + 0.02 * (frame - FIRST_FRAME) as f64;
    let eye = DVec3::new(8.5 * angle.sin(), -8.5 * angle.cos(), 3.2);
    look_at(eye, DVec3::new(0.0, 0.5, 1.0))
}

fn intrinsics(width: u32, height: u32) -> BlenderIntrinsics {
    BlenderIntrinsics {
        lens: 40.0,
        sensor_width: 36.0,
        sensor_height: 24.0,
        sensor_fit: SensorFit::Auto,
        resolution_x: width,
        resolution_y: height,
        ..BlenderIntrinsics::default()
    }
}

/// The demo shot: [`FRAMES`] frames from [`FIRST_FRAME`] at `width × height`.
pub fn shot(width: u32, height: u32) -> Shot {
    let b = intrinsics(width, height);
    let frames = (FIRST_FRAME..FIRST_FRAME + FRAMES)
        .map(|frame| ShotFrame {
            frame,
            camera: ShotCamera {
                world_from_camera: camera_matrix(frame),
                kind: ShotCameraKind::Perspective,
                lens: b.lens,
                sensor_width: b.sensor_width,
                sensor_height: b.sensor_height,
                sensor_fit: b.sensor_fit,
                shift_x: b.shift_x,
                shift_y: b.shift_y,
                clip_start: CLIP[0],
                clip_end: CLIP[1],
                stereo: None,
                dof: None,
            },
            objects: BTreeMap::from([(NERF_OBJECT.to_string(), object_matrix(frame))]),
        })
        .collect();
    Shot {
        fps: 24.0,
        fps_base: 1.0,
        resolution_x: width,
        resolution_y: height,
        resolution_percentage: 100,
        pixel_aspect_x: 1.0,
        pixel_aspect_y: 1.0,
        nerf_object: NERF_OBJECT.into(),
        frames,
        motion_blur: None,
        scene_world: SceneWorld::Blender,
        source: PathBuf::new(),
    }
}

/// The demo scene placed at its first frame, and the camera, at `width × height`.
pub fn scene_and_camera(width: u32, height: u32) -> Result<(Scene, Camera)> {
    let scene = scene_desc()
        .load()?
        .place(DMat4::IDENTITY, &|_| Ok(object_matrix(FIRST_FRAME)))?;
    let projection =
        Projection::Perspective(Perspective::from_blender(&intrinsics(width, height))?);
    let camera =
        Camera::new(camera_matrix(FIRST_FRAME), projection)?.with_clip(CLIP[0], CLIP[1])?;
    Ok((scene, camera))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn look_at_points_minus_z_at_the_target() {
        let m = look_at(DVec3::new(3.0, -4.0, 2.0), DVec3::new(0.0, 0.0, 2.0));
        let view = m.transform_vector3(DVec3::NEG_Z);
        assert!((view - DVec3::new(-0.6, 0.8, 0.0)).length() < 1e-12);
        assert!((m.transform_vector3(DVec3::Y) - DVec3::Z).length() < 1e-12);
        assert!((m.determinant() - 1.0).abs() < 1e-12);
        let down = look_at(DVec3::new(0.0, 0.0, 5.0), DVec3::ZERO);
        assert!(down.is_finite());
        assert!((down.transform_vector3(DVec3::NEG_Z) - DVec3::NEG_Z).length() < 1e-12);
    }

    #[test]
    fn the_demo_shot_places_the_object_like_the_direct_scene() {
        let shot = shot(64, 36);
        let frame = shot.frame(FIRST_FRAME).unwrap();
        assert_eq!(
            frame.object_matrix(NERF_OBJECT).unwrap(),
            object_matrix(FIRST_FRAME)
        );
        let (_, camera) = scene_and_camera(64, 36).unwrap();
        assert_eq!(frame.camera(&shot).unwrap(), camera);
    }
}
