//! PLACEHOLDER — the field helper replaces this file.
/// Analytic.
pub struct Analytic;
/// Primitive.
pub struct Primitive;
/// Shape.
pub enum Shape {}
