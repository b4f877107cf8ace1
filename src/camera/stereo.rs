//! PLACEHOLDER — the camera helper replaces this file.
use super::CameraRay;
/// Vr180.
#[derive(Clone, Debug, PartialEq)]
pub struct Vr180;
impl Vr180 {
    /// Resolution.
    pub fn resolution(&self) -> (u32, u32) {
        todo!()
    }
    /// Ray.
    pub fn camera_ray(&self, _x: f64, _y: f64) -> Option<CameraRay> {
        todo!()
    }
}
/// Ods.
#[derive(Clone, Debug, PartialEq)]
pub struct Ods;
impl Ods {
    /// Resolution.
    pub fn resolution(&self) -> (u32, u32) {
        todo!()
    }
    /// Ray.
    pub fn camera_ray(&self, _x: f64, _y: f64) -> Option<CameraRay> {
        todo!()
    }
}
/// Eye.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Eye {
    /// Left.
    Left,
}
