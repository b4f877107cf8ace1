//! PLACEHOLDER — the camera helper replaces this file.
use super::CameraRay;
/// Equirect.
#[derive(Clone, Debug, PartialEq)]
pub struct Equirect;
impl Equirect {
    /// Resolution.
    pub fn resolution(&self) -> (u32, u32) {
        todo!()
    }
    /// Ray.
    pub fn camera_ray(&self, _x: f64, _y: f64) -> Option<CameraRay> {
        todo!()
    }
}
