//! Compositing: small named pure functions on premultiplied float RGBA [`Planes`].
//!
//! Every function takes whole planes of one size (top row first) and returns new planes:
//! [`over()`], [`mix()`], [`accumulation_matte()`], [`shadow_catcher_merge()`],
//! [`depth_merge()`], [`shutter_average()`]. The
//! per-pixel formula of each is in its docs with a three-pixel worked example.
//!
//! **Reading pixels** ([`rgba_pixels`]): missing RGB reads as black; missing alpha reads as 1
//! when RGB is present (an image without alpha is opaque) and 0 otherwise.
//!
//! **Non-finite input is sanitised, not passed through**: NaN and ±inf colour or alpha samples
//! read as 0, so every output of these functions is finite (a NaN in one plate must not spread
//! through a comp). Depth samples that are NaN, +inf or ≥ [`BACKGROUND_DEPTH`] mean "nothing
//! there" and count as infinitely far (see [`depth_merge()`]).
//!
//! ```
//! use nerfx_core::composite::{over, rgba_pixels, rgba_planes};
//! let a = rgba_planes(1, 1, &[[0.5, 0.0, 0.0, 0.5]]).unwrap();
//! let b = rgba_planes(1, 1, &[[0.0, 0.0, 1.0, 1.0]]).unwrap();
//! assert_eq!(rgba_pixels(&over(&a, &b).unwrap()), vec![[0.5, 0.0, 0.5, 1.0]]);
//! ```

mod accumulation_matte;
mod depth_merge;
mod mix;
mod over;
mod shadow_catcher;
mod shutter;

pub use accumulation_matte::{accumulation_matte, MatteCurve};
pub use depth_merge::depth_merge;
pub use mix::mix;
pub use over::over;
pub use shadow_catcher::shadow_catcher_merge;
pub use shutter::shutter_average;

use crate::error::{number, Error, Result};
use crate::image::{Plane, Planes, BACKGROUND_DEPTH};

/// One premultiplied pixel: red, green, blue, alpha.
pub type Rgba = [f32; 4];

/// A finite sample, or 0 for NaN and ±inf.
fn finite(v: f32) -> f32 {
    if v.is_finite() {
        v
    } else {
        0.0
    }
}

/// A depth sample with "nothing there" (NaN, +inf, ≥ [`BACKGROUND_DEPTH`]) as +inf.
fn depth(z: f32) -> f32 {
    if z.is_nan() || z >= BACKGROUND_DEPTH {
        f32::INFINITY
    } else {
        z
    }
}

/// The pixels of `planes`, row-major, sanitised as the module docs say.
pub fn rgba_pixels(planes: &Planes) -> Vec<Rgba> {
    let n = planes.width as usize * planes.height as usize;
    let opaque = if planes.rgb.is_some() { 1.0 } else { 0.0 };
    (0..n)
        .map(|i| {
            let c = |c: usize| {
                planes
                    .rgb
                    .as_ref()
                    .map_or(0.0, |rgb| finite(rgb[c].data[i]))
            };
            let a = planes.alpha.as_ref().map_or(opaque, |p| finite(p.data[i]));
            [c(0), c(1), c(2), a]
        })
        .collect()
}

/// Planes holding RGB and alpha of `pixels` (row-major, `width × height` of them).
pub fn rgba_planes(width: u32, height: u32, pixels: &[Rgba]) -> Result<Planes> {
    if pixels.len() != width as usize * height as usize {
        return Err(Error::invalid(
            "composite image",
            format!("{} pixels for {width}×{height}", pixels.len()),
        ));
    }
    let plane = |c: usize| Plane {
        width,
        height,
        data: pixels.iter().map(|p| p[c]).collect(),
    };
    Ok(Planes {
        width,
        height,
        rgb: Some([plane(0), plane(1), plane(2)]),
        alpha: Some(plane(3)),
        depth_z: None,
        depth_ray: None,
        depth_median: None,
    })
}

/// Refuses inputs of different sizes; `inputs` are (name, width, height) for the message.
fn same_size(what: &str, inputs: &[(&str, u32, u32)]) -> Result<(u32, u32)> {
    let (_, w, h) = inputs[0];
    if let Some((name, iw, ih)) = inputs.iter().find(|&&(_, iw, ih)| (iw, ih) != (w, h)) {
        return Err(Error::invalid(
            what,
            format!("{name} is {iw}×{ih} but {} is {w}×{h}", inputs[0].0),
        ));
    }
    Ok((w, h))
}

/// Refuses a parameter that is not finite or outside `[lo, hi]`.
fn check_range(what: &str, name: &str, v: f32, lo: f32, hi: f32) -> Result<()> {
    if !(v.is_finite() && (lo..=hi).contains(&v)) {
        return Err(Error::invalid(
            what,
            format!("{name} must be in [{lo}, {hi}], got {}", number(v)),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_planes_read_as_black_and_opaque_or_transparent() {
        let mut p = rgba_planes(1, 1, &[[0.1, 0.2, 0.3, 0.4]]).unwrap();
        p.alpha = None;
        assert_eq!(rgba_pixels(&p), vec![[0.1, 0.2, 0.3, 1.0]]);
        p.rgb = None;
        p.alpha = Some(Plane::filled(1, 1, 0.5));
        assert_eq!(rgba_pixels(&p), vec![[0.0, 0.0, 0.0, 0.5]]);
    }

    #[test]
    fn non_finite_samples_read_as_zero_and_far_depth_as_nothing() {
        let p = rgba_planes(1, 1, &[[f32::NAN, f32::INFINITY, -f32::INFINITY, f32::NAN]]).unwrap();
        assert_eq!(rgba_pixels(&p), vec![[0.0; 4]]);
        assert_eq!(depth(1e10), f32::INFINITY);
        assert_eq!(depth(f32::NAN), f32::INFINITY);
        assert_eq!(depth(3.5), 3.5);
    }

    #[test]
    fn sizes_and_ranges_are_checked() {
        let e = same_size("over", &[("A", 2, 2), ("B", 2, 3)]).unwrap_err();
        assert!(e.to_string().contains("B is 2×3 but A is 2×2"), "{e}");
        assert!(check_range("mix", "amount", 1.5, 0.0, 1.0).is_err());
        assert!(check_range("mix", "amount", f32::NAN, 0.0, 1.0).is_err());
        assert!(rgba_planes(2, 1, &[[0.0; 4]]).is_err());
    }
}
