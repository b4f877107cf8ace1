//! PLACEHOLDER — the field helper replaces this file.
use glam::Vec3;
/// Aabb.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Min.
    pub min: Vec3,
    /// Max.
    pub max: Vec3,
}
