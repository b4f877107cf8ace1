//! PLACEHOLDER — the camera helper replaces this file.
use super::CameraRay;
/// Sensor fit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum SensorFit {
    /// Auto.
    #[default]
    Auto,
    /// Horizontal.
    Horizontal,
    /// Vertical.
    Vertical,
}
/// Perspective.
#[derive(Clone, Debug, PartialEq)]
pub struct Perspective;
impl Perspective {
    /// Resolution.
    pub fn resolution(&self) -> (u32, u32) {
        todo!()
    }
    /// Ray.
    pub fn camera_ray(&self, _x: f64, _y: f64) -> Option<CameraRay> {
        todo!()
    }
}
