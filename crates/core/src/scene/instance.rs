//! One placed field, and a world ray carried into its frame.

use std::sync::{Arc, Mutex};

use glam::{DMat4, DVec3, DVec4, Vec3};

use super::{CropBox, CropClip};
use crate::camera::Ray;
use crate::error::{Error, Result};
use crate::field::{Analytic, Field, Line, Occupancy};

/// A loaded field, shared by every instance and frame that uses it, with its occupancy
/// structures (built on first use, one per resolution a quality preset asks for).
#[derive(Clone)]
pub struct FieldHandle(Arc<FieldInner>);

struct FieldInner {
    field: Arc<dyn Field>,
    analytic: Option<Arc<Analytic>>,
    occupancy: Mutex<Vec<Arc<Occupancy>>>,
}

impl FieldHandle {
    /// Any field.
    pub fn new(field: Arc<dyn Field>) -> Self {
        Self::with_analytic(field, None)
    }

    /// An analytic field; the reference integrator can see its primitives.
    pub fn analytic(field: Analytic) -> Self {
        let analytic = Arc::new(field);
        Self::with_analytic(analytic.clone(), Some(analytic))
    }

    fn with_analytic(field: Arc<dyn Field>, analytic: Option<Arc<Analytic>>) -> Self {
        FieldHandle(Arc::new(FieldInner {
            field,
            analytic,
            occupancy: Mutex::new(Vec::new()),
        }))
    }

    /// The same field coloured `rgb` everywhere ([`super::indicator`]), its occupancy
    /// structures shared (they depend on density alone).
    pub(crate) fn with_indicator_colour(&self, rgb: Vec3) -> FieldHandle {
        let occupancy = self
            .0
            .occupancy
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone();
        let (field, analytic): (Arc<dyn Field>, _) = match self.as_analytic() {
            Some(a) => {
                let mut a = a.clone();
                for p in &mut a.primitives {
                    p.color = crate::field::ShColor::constant(rgb);
                }
                let a = Arc::new(a);
                (a.clone(), Some(a))
            }
            None => (
                Arc::new(super::indicator::Indicator {
                    field: self.0.field.clone(),
                    rgb,
                }),
                None,
            ),
        };
        FieldHandle(Arc::new(FieldInner {
            field,
            analytic,
            occupancy: Mutex::new(occupancy),
        }))
    }

    /// The field.
    pub fn field(&self) -> &dyn Field {
        self.0.field.as_ref()
    }

    /// The analytic description, when the field is analytic.
    pub fn as_analytic(&self) -> Option<&Analytic> {
        self.0.analytic.as_deref()
    }

    /// The occupancy structure at `resolution`, built on first request.
    pub(crate) fn occupancy(&self, resolution: u32) -> Arc<Occupancy> {
        // A poisoned lock only means another thread panicked while building; the list
        // itself is always valid.
        let mut built = self.0.occupancy.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(o) = built.iter().find(|o| o.resolution() == resolution) {
            return o.clone();
        }
        let o = Arc::new(Occupancy::build(self.field(), resolution));
        built.push(o.clone());
        o
    }
}

/// A field placed in the world.
#[derive(Clone)]
pub struct Instance {
    /// A name for messages (the scene file's instance name).
    pub name: String,
    field: FieldHandle,
    world_from_field: DMat4,
    field_from_world: DMat4,
    crop: Option<CropBox>,
    /// The crop box ready to clip rays.
    crop_clip: Option<CropClip>,
    /// The field's bounds, in f64, and the interval its near and far distances allow
    /// (`[0, ∞)` for a bounded field): fixed for the field, so taken once here rather than
    /// asked of it on every ray.
    clip: Clip,
}

/// What [`Instance::clip_local`] needs of the field, taken once per instance.
#[derive(Clone, Copy, Debug)]
struct Clip {
    min: DVec3,
    max: DVec3,
    near: f64,
    far: f64,
}

impl Clip {
    fn of(field: &dyn Field) -> Self {
        let b = field.bounds();
        let (near, far) = field.unbounded().map_or((0.0f64, f64::INFINITY), |u| {
            (f64::from(u.near).max(0.0), f64::from(u.far))
        });
        Clip {
            min: b.min.as_dvec3(),
            max: b.max.as_dvec3(),
            near,
            far,
        }
    }
}

/// A world ray seen from one instance: the part of it inside the field's bounds and crop.
///
/// A sample at world distance `t ∈ [t_near, t_far]` is at
/// `origin + (t − t_near)·units_per_world·dir` in field space; density σ per field unit is
/// `units_per_world·σ` per world unit. The origin is the entry point (computed in f64) so f32
/// positions stay precise however far the camera is from the field.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LocalRay {
    /// Field-space position at `t_near`.
    pub origin: Vec3,
    /// Unit field-space direction.
    pub dir: Vec3,
    /// Field units per world unit along this ray (`|field_from_world · d|`).
    pub units_per_world: f32,
    /// World distance where the ray enters the field's bounds (and crop).
    pub t_near: f64,
    /// World distance where it leaves them.
    pub t_far: f64,
}

impl LocalRay {
    /// Field-space position at world distance `t`.
    #[inline]
    pub fn at(&self, t: f64) -> Vec3 {
        self.origin + self.dir * ((t - self.t_near) as f32 * self.units_per_world)
    }
}

/// A world ray seen from one instance, in `f64` ([`Instance::local_line`]): at world distance
/// `t` it is at `line.origin() + t·line.velocity()` in field space, inside the field's bounds
/// and crop for `t ∈ [t_near, t_far]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct LocalLine {
    /// From the field-space position of the world ray's origin, field units moved per world
    /// unit (`field_from_world · d`, unnormalised), with the reciprocals that clipped it.
    pub(crate) line: Line,
    /// The velocity as a unit direction.
    pub(crate) dir: DVec3,
    /// `|velocity|`.
    pub(crate) units_per_world: f64,
    /// World distance where the ray enters the field's bounds (and crop).
    pub(crate) t_near: f64,
    /// World distance where it leaves them.
    pub(crate) t_far: f64,
}

/// Checks an instance's placement and crop box; returns the placement's inverse. Refuses
/// matrices with NaN/inf, a projective row or no inverse.
pub(super) fn check_placement(
    name: &str,
    world_from_field: DMat4,
    crop: Option<&CropBox>,
) -> Result<DMat4> {
    let what = format!("instance '{name}': world_from_field");
    if !world_from_field.is_finite() {
        return Err(Error::invalid(what, "contains NaN or infinity"));
    }
    if world_from_field.row(3) != DVec4::new(0.0, 0.0, 0.0, 1.0) {
        return Err(Error::invalid(what, "bottom row must be [0, 0, 0, 1]"));
    }
    let m3 = glam::DMat3::from_mat4(world_from_field);
    let scale = m3
        .x_axis
        .length()
        .max(m3.y_axis.length())
        .max(m3.z_axis.length());
    if m3.determinant().abs() <= 1e-15 * scale.powi(3) || scale == 0.0 {
        return Err(Error::invalid(what, "is singular (a zero scale?)"));
    }
    let field_from_world = world_from_field.inverse();
    if !field_from_world.is_finite() {
        return Err(Error::invalid(what, "cannot be inverted"));
    }
    if let Some(c) = crop {
        c.validate(&format!("instance '{name}': crop"))?;
    }
    Ok(field_from_world)
}

impl Instance {
    /// Places `field` by `world_from_field` (the NeRF object's `matrix_world`). Refuses
    /// matrices with NaN/inf, a projective row or no inverse.
    pub fn new(
        name: impl Into<String>,
        field: FieldHandle,
        world_from_field: DMat4,
        crop: Option<CropBox>,
    ) -> Result<Self> {
        let name = name.into();
        let field_from_world = check_placement(&name, world_from_field, crop.as_ref())?;
        let clip = Clip::of(field.field());
        Ok(Instance {
            name,
            clip,
            field,
            world_from_field,
            field_from_world,
            crop_clip: crop.as_ref().map(CropBox::clipper),
            crop,
        })
    }

    /// The field and its caches.
    pub fn handle(&self) -> &FieldHandle {
        &self.field
    }

    /// The field.
    pub fn field(&self) -> &dyn Field {
        self.field.field()
    }

    /// `N`, the object transform.
    pub fn world_from_field(&self) -> DMat4 {
        self.world_from_field
    }

    /// `N⁻¹`.
    pub fn field_from_world(&self) -> DMat4 {
        self.field_from_world
    }

    /// The crop box, in field space.
    pub fn crop(&self) -> Option<&CropBox> {
        self.crop.as_ref()
    }

    /// The crop box ready to clip rays.
    pub(crate) fn crop_clip(&self) -> Option<&CropClip> {
        self.crop_clip.as_ref()
    }

    /// The interval `[t0, t1]` of the field-space line (`t` in world units, `inv_k` the
    /// inverse of its speed) inside the field's bounds and the crop box; for an unbounded
    /// field, also between its near and far distances (field units) from the line's origin.
    /// Clipped in world units directly, with the line's reciprocals, which its primitives'
    /// intervals take too: no division per axis here.
    fn clip_local(&self, line: &Line, inv_k: f64) -> Option<(f64, f64)> {
        let Clip {
            min,
            max,
            near,
            far,
        } = self.clip;
        let [lo, hi] = line.box_interval(min, max)?;
        let (lo, hi) = (lo.max(near * inv_k), hi.min(far * inv_k));
        if lo > hi {
            return None;
        }
        match &self.crop_clip {
            Some(c) => c.clip(line.origin(), line.velocity(), lo, hi),
            None => Some((lo, hi)),
        }
    }

    /// The world ray within `[t_min, t_max]` carried into this instance's frame and clipped
    /// to its bounds and crop; `None` when it misses them.
    pub fn local_ray(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<LocalRay> {
        let line = self.local_line(ray, t_min, t_max)?;
        Some(LocalRay {
            origin: (line.line.origin() + line.dir * (line.t_near * line.units_per_world))
                .as_vec3(),
            dir: line.dir.as_vec3(),
            units_per_world: line.units_per_world as f32,
            t_near: line.t_near,
            t_far: line.t_far,
        })
    }

    /// [`local_ray`](Self::local_ray) in `f64`, for those who integrate along the line rather
    /// than sample it in `f32`.
    #[inline(always)]
    pub(crate) fn local_line(&self, ray: &Ray, t_min: f64, t_max: f64) -> Option<LocalLine> {
        let line = Line::new(
            self.field_from_world.transform_point3(ray.origin),
            self.field_from_world.transform_vector3(ray.dir),
        );
        let k = line.velocity().length();
        // A ray without a direction (or one the placement sends to infinity) meets nothing.
        if !(k > 0.0 && k.is_finite()) {
            return None;
        }
        let inv_k = 1.0 / k;
        let (t0, t1) = self.clip_local(&line, inv_k)?;
        let (t_near, t_far) = (t0.max(t_min), t1.min(t_max));
        if t_near.is_nan() || t_far.is_nan() || t_near >= t_far {
            return None;
        }
        Some(LocalLine {
            line,
            dir: line.velocity() * inv_k,
            units_per_world: k,
            t_near,
            t_far,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::{Primitive, ShColor, Shape};

    fn unit_sphere_field() -> FieldHandle {
        FieldHandle::analytic(Analytic {
            primitives: vec![Primitive {
                shape: Shape::Sphere {
                    center: Vec3::ZERO,
                    radius: 1.0,
                },
                density: 1.0,
                color: ShColor::constant(Vec3::ONE),
            }],
        })
    }

    #[test]
    fn non_uniform_scale_keeps_world_distances() {
        // N scales x by 2, y by 3, z by 0.5 and moves the field to (10, 0, 0).
        let n = DMat4::from_translation(DVec3::new(10.0, 0.0, 0.0))
            * DMat4::from_scale(DVec3::new(2.0, 3.0, 0.5));
        let inst = Instance::new("s", unit_sphere_field(), n, None).unwrap();
        // A ray along world +x from the origin: enters the (stretched) sphere at x = 8.
        let ray = Ray {
            origin: DVec3::ZERO,
            dir: DVec3::X,
            z_per_t: 1.0,
            near: 0.0,
            far: f64::INFINITY,
        };
        let lr = inst.local_ray(&ray, 0.0, 1e9).unwrap();
        assert!((lr.units_per_world - 0.5).abs() < 1e-7);
        // Bounds of the unit sphere are [-1, 1]³ → world x ∈ [8, 12].
        assert!((lr.t_near - 8.0).abs() < 1e-9 && (lr.t_far - 12.0).abs() < 1e-9);
        let p = lr.at(11.0);
        assert!((p - Vec3::new(0.5, 0.0, 0.0)).length() < 1e-6);
        // Along world y the field is 3× stretched: 1 world unit is 1/3 field unit.
        let ray_y = Ray {
            origin: DVec3::new(10.0, -10.0, 0.0),
            dir: DVec3::Y,
            z_per_t: 1.0,
            near: 0.0,
            far: f64::INFINITY,
        };
        let ly = inst.local_ray(&ray_y, 0.0, 1e9).unwrap();
        assert!((ly.units_per_world as f64 - 1.0 / 3.0).abs() < 1e-7);
        assert!((ly.t_near - 7.0).abs() < 1e-9 && (ly.t_far - 13.0).abs() < 1e-9);
    }

    #[test]
    fn bad_matrices_are_refused_with_the_instance_name() {
        let mut m = DMat4::IDENTITY;
        m.x_axis.x = f64::NAN;
        let e = Instance::new("env", unit_sphere_field(), m, None)
            .err()
            .unwrap();
        assert!(e.to_string().contains("env"), "{e}");
        let e = Instance::new(
            "obj",
            unit_sphere_field(),
            DMat4::from_scale(DVec3::new(1.0, 0.0, 1.0)),
            None,
        )
        .err()
        .unwrap();
        assert!(e.to_string().contains("singular"), "{e}");
    }

    #[test]
    fn far_from_origin_positions_stay_precise() {
        let n = DMat4::from_translation(DVec3::splat(1e5));
        let inst = Instance::new("far", unit_sphere_field(), n, None).unwrap();
        let ray = Ray {
            origin: DVec3::new(1e5, 1e5, 1e5 + 5.0),
            dir: DVec3::NEG_Z,
            z_per_t: 1.0,
            near: 0.0,
            far: f64::INFINITY,
        };
        let lr = inst.local_ray(&ray, 0.0, f64::INFINITY).unwrap();
        assert!((lr.t_near - 4.0).abs() < 1e-9);
        assert!((lr.at(5.25) - Vec3::new(0.0, 0.0, -0.25)).length() < 1e-6);
    }
}
