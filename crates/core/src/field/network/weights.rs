//! Trained weights are checked once at load: a training that diverged saves NaN or infinite
//! weights, and a field built from them renders nothing (every sample's density is NaN, which
//! the marcher reads as empty) without a word. Refusing them at load names the file and the
//! block, before a frame is rendered.

/// `None` when every value is finite, else what is wrong with them in a user's terms.
pub(crate) fn non_finite(values: &[f32]) -> Option<String> {
    let first = values.iter().position(|v| !v.is_finite())?;
    let count = values.iter().filter(|v| !v.is_finite()).count();
    Some(format!(
        "{count} of {} weights are NaN or infinite (the first at index {first}, {}): the \
         training diverged before this was saved; use an earlier checkpoint or retrain",
        values.len(),
        values[first]
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_how_many_and_the_first() {
        assert_eq!(non_finite(&[0.0, -1.0, 1e30]), None);
        let m = non_finite(&[0.0, f32::INFINITY, f32::NAN, 2.0]).unwrap();
        assert!(
            m.starts_with("2 of 4 weights") && m.contains("index 1, inf"),
            "{m}"
        );
    }
}
