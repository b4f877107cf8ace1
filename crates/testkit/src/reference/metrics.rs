//! How far a render is from the reference: PSNR of the colour, the largest alpha and
//! premultiplied colour errors (what a quality preset's error target bounds) and the largest
//! relative depth error where the surface is solid.
//!
//! ```
//! use nerfx_core::image::{Plane, Planes};
//! use nerfx_testkit::reference::metrics::{max_abs_error, psnr};
//! let grey = |v: f32| Plane::filled(2, 2, v);
//! let planes = |v: f32| Planes {
//!     width: 2, height: 2,
//!     rgb: Some([grey(v), grey(v), grey(v)]),
//!     alpha: Some(grey(1.0)), depth_z: None, depth_ray: None, depth_median: None,
//! };
//! // Every channel off by 0.01: MSE 1e-4, PSNR 40 dB.
//! assert!((psnr(&planes(0.5), &planes(0.51)) - 40.0).abs() < 1e-4);
//! assert_eq!(max_abs_error(&grey(1.0), &grey(1.0)), 0.0);
//! ```

use std::fmt;

use nerfx_core::image::{Plane, Planes};

/// Depth is compared only where the reference accumulation is at least this: the depth of
/// a barely visible pixel is an average over a little density anywhere along the ray, so
/// it is ill-defined (and a marcher that stops early or skips faint space may legitimately
/// place it anywhere), while where the surface is at least half opaque it is what a
/// compositor's depth merge relies on.
pub const DEPTH_ALPHA_THRESHOLD: f64 = 0.5;

/// Peak signal-to-noise ratio of `test` against `reference` in dB, over premultiplied RGB
/// with peak 1: `−10·log₁₀(MSE)`, the MSE over all pixels and the three channels; `+∞` when
/// they are identical. NaN when either lacks RGB or the sizes differ.
pub fn psnr(reference: &Planes, test: &Planes) -> f64 {
    let (Some(r), Some(t)) = (&reference.rgb, &test.rgb) else {
        return f64::NAN;
    };
    let mut sum = 0.0;
    let mut count = 0usize;
    for (a, b) in r.iter().zip(t) {
        if a.width != b.width || a.height != b.height || a.data.len() != b.data.len() {
            return f64::NAN;
        }
        sum += a
            .data
            .iter()
            .zip(&b.data)
            .map(|(&x, &y)| (x as f64 - y as f64).powi(2))
            .sum::<f64>();
        count += a.data.len();
    }
    if count == 0 {
        return f64::NAN;
    }
    -10.0 * (sum / count as f64).log10()
}

/// The largest `|a − b|` over all pixels. Pixels where both are `+∞` (nothing hit, in a
/// depth plane) are equal and skipped; where exactly one is infinite the error is `+∞`.
/// NaN when the sizes differ or a sample is NaN.
pub fn max_abs_error(a: &Plane, b: &Plane) -> f64 {
    if a.width != b.width || a.height != b.height || a.data.len() != b.data.len() {
        return f64::NAN;
    }
    let mut worst = 0.0f64;
    for (&x, &y) in a.data.iter().zip(&b.data) {
        if x == y {
            continue; // Also both +∞.
        }
        let e = (x as f64 - y as f64).abs();
        if e.is_nan() {
            return f64::NAN;
        }
        worst = worst.max(e);
    }
    worst
}

/// The larger of `a` and `b`, NaN if either is (a NaN error fails every threshold).
pub fn nan_max(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.max(b)
    }
}

/// The largest relative camera-Z error `|z_test − z_ref| / z_ref` over the pixels where
/// the reference alpha is at least [`DEPTH_ALPHA_THRESHOLD`] (see there for why); 0 when
/// there are none, `+∞` where the test has no depth but the reference does. NaN when a
/// plane is missing or the sizes differ.
pub fn depth_error(reference: &Planes, test: &Planes) -> f64 {
    let (Some(alpha), Some(zr), Some(zt)) = (&reference.alpha, &reference.depth_z, &test.depth_z)
    else {
        return f64::NAN;
    };
    let n = alpha.data.len();
    if zr.data.len() != n
        || zt.data.len() != n
        || (test.width, test.height) != (reference.width, reference.height)
    {
        return f64::NAN;
    }
    let mut worst = 0.0f64;
    for ((&a, &r), &t) in alpha.data.iter().zip(&zr.data).zip(&zt.data) {
        if (a as f64) < DEPTH_ALPHA_THRESHOLD || r == t {
            continue;
        }
        let e = (t as f64 - r as f64).abs() / (r as f64).abs();
        if e.is_nan() {
            return f64::NAN;
        }
        worst = worst.max(e);
    }
    worst
}

/// A render's distance from the reference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ErrorReport {
    /// [`psnr`] of premultiplied RGB, dB.
    pub psnr: f64,
    /// [`max_abs_error`] of the alpha planes.
    pub max_alpha_error: f64,
    /// The largest [`max_abs_error`] of the three premultiplied colour planes.
    pub max_color_error: f64,
    /// [`depth_error`]: the largest relative camera-Z error where the reference is solid.
    pub max_depth_rel_error: f64,
}

impl ErrorReport {
    /// Compares `test` with `reference`. A metric whose planes are missing from either, or
    /// whose sizes differ, is NaN (so it fails any threshold it is checked against).
    pub fn compare(reference: &Planes, test: &Planes) -> ErrorReport {
        let max_alpha_error = match (&reference.alpha, &test.alpha) {
            (Some(a), Some(b)) => max_abs_error(a, b),
            _ => f64::NAN,
        };
        let max_color_error = match (&reference.rgb, &test.rgb) {
            (Some(a), Some(b)) => a
                .iter()
                .zip(b)
                .map(|(a, b)| max_abs_error(a, b))
                .fold(0.0, nan_max),
            _ => f64::NAN,
        };
        ErrorReport {
            psnr: psnr(reference, test),
            max_alpha_error,
            max_color_error,
            max_depth_rel_error: depth_error(reference, test),
        }
    }
}

impl fmt::Display for ErrorReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "PSNR {:.2} dB, max alpha error {:.2e}, max colour error {:.2e}, max depth error \
             {:.3} %",
            self.psnr,
            self.max_alpha_error,
            self.max_color_error,
            100.0 * self.max_depth_rel_error
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plane(data: &[f32]) -> Plane {
        Plane {
            width: data.len() as u32,
            height: 1,
            data: data.to_vec(),
        }
    }

    fn planes(rgb: f32, alpha: &[f32], z: &[f32]) -> Planes {
        let n = alpha.len();
        Planes {
            width: n as u32,
            height: 1,
            rgb: Some([
                plane(&vec![rgb; n]),
                plane(&vec![0.0; n]),
                plane(&vec![0.0; n]),
            ]),
            alpha: Some(plane(alpha)),
            depth_z: Some(plane(z)),
            depth_ray: None,
            depth_median: None,
        }
    }

    #[test]
    fn psnr_of_a_known_mse() {
        // One channel of three off by 0.1 everywhere: MSE = 0.01/3.
        let a = planes(0.2, &[1.0, 1.0], &[1.0, 1.0]);
        let b = planes(0.3, &[1.0, 1.0], &[1.0, 1.0]);
        let want = -10.0 * (0.01f64 / 3.0).log10();
        assert!((psnr(&a, &b) - want).abs() < 1e-5, "{}", psnr(&a, &b));
        assert_eq!(psnr(&a, &a), f64::INFINITY);
    }

    #[test]
    fn infinities_in_depth_planes() {
        let inf = f32::INFINITY;
        assert_eq!(max_abs_error(&plane(&[inf, 1.0]), &plane(&[inf, 1.5])), 0.5);
        assert_eq!(
            max_abs_error(&plane(&[inf, 1.0]), &plane(&[2.0, 1.0])),
            f64::INFINITY
        );
        assert!(max_abs_error(&plane(&[f32::NAN]), &plane(&[1.0])).is_nan());
        assert!(max_abs_error(&plane(&[1.0]), &plane(&[1.0, 2.0])).is_nan());
    }

    #[test]
    fn depth_error_ignores_faint_pixels() {
        // Pixel 0 is solid and 10 % off; pixel 1 is faint and way off; pixel 2 is empty.
        let inf = f32::INFINITY;
        let r = planes(0.0, &[0.9, 0.2, 0.0], &[2.0, 3.0, inf]);
        let t = planes(0.0, &[0.9, 0.2, 0.0], &[2.2, 30.0, inf]);
        assert!((depth_error(&r, &t) - 0.1).abs() < 1e-6);
        // A solid pixel the test misses entirely is an infinite error.
        let t = planes(0.0, &[0.9, 0.2, 0.0], &[inf, 3.0, inf]);
        assert_eq!(depth_error(&r, &t), f64::INFINITY);
    }

    #[test]
    fn report_marks_what_cannot_be_compared_as_nan() {
        let r = planes(0.5, &[1.0, 0.5], &[1.0, 2.0]);
        let mut t = planes(0.5, &[0.75, 0.5], &[1.0, 2.0]);
        let e = ErrorReport::compare(&r, &t);
        assert_eq!(e.psnr, f64::INFINITY);
        assert_eq!(e.max_alpha_error, 0.25);
        assert_eq!(e.max_depth_rel_error, 0.0);
        t.depth_z = None;
        let e = ErrorReport::compare(&r, &t);
        assert!(e.max_depth_rel_error.is_nan() && e.max_alpha_error == 0.25);
        let small = planes(0.5, &[1.0], &[1.0]);
        assert!(ErrorReport::compare(&r, &small).psnr.is_nan());
    }

    #[test]
    fn colour_error_is_the_worst_channel_of_the_worst_pixel() {
        let r = planes(0.5, &[1.0, 0.5], &[1.0, 2.0]);
        let mut t = planes(0.5, &[1.0, 0.5], &[1.0, 2.0]);
        assert_eq!(ErrorReport::compare(&r, &t).max_color_error, 0.0);
        if let Some(rgb) = &mut t.rgb {
            rgb[0].data[1] = 0.25;
            rgb[2].data[0] = 0.125;
        }
        assert_eq!(ErrorReport::compare(&r, &t).max_color_error, 0.25);
        if let Some(rgb) = &mut t.rgb {
            rgb[1].data[0] = f32::NAN;
        }
        assert!(ErrorReport::compare(&r, &t).max_color_error.is_nan());
        t.rgb = None;
        assert!(ErrorReport::compare(&r, &t).max_color_error.is_nan());
    }
}
