//! The density activation both trained fields use: `exp` of the network's output.

/// Largest exponent fed to `exp`: σ stays finite (`e^80 ≈ 5.5·10³⁴`, opaque over any step).
const MAX_LOG_DENSITY: f32 = 80.0;

/// `exp(raw)`, the exponent capped at [`MAX_LOG_DENSITY`]. A NaN output (a network whose
/// sums overflowed) stays NaN rather than becoming opaque: the renderers take it as empty
/// and count it.
#[inline]
pub(crate) fn exp_density(raw: f32) -> f32 {
    if raw > MAX_LOG_DENSITY {
        MAX_LOG_DENSITY.exp()
    } else {
        raw.exp()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn capped_above_and_nan_kept() {
        assert_eq!(exp_density(0.0), 1.0);
        assert_eq!(exp_density(1e9), 80f32.exp());
        assert_eq!(exp_density(f32::INFINITY), 80f32.exp());
        assert_eq!(exp_density(f32::NEG_INFINITY), 0.0);
        assert!(exp_density(f32::NAN).is_nan());
    }
}
