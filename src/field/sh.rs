//! PLACEHOLDER — the field helper replaces this file.
/// ShColor.
pub struct ShColor;
