//! PLACEHOLDER — the field helper replaces this file.
/// Occupancy.
pub struct Occupancy;
