//! PLACEHOLDER — the image helper replaces this file.
/// Write.
pub fn write_exr() {}
