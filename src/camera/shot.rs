//! PLACEHOLDER — the camera helper replaces this file.
/// Shot.
pub struct Shot;
/// Frame.
pub struct ShotFrame;
