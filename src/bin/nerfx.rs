//! PLACEHOLDER.
fn main() {}
