//! The average of a frame's renders over the shutter interval (motion blur).

use super::{depth, finite};
use crate::error::{Error, Result};
use crate::image::{Plane, Planes};

/// The mean of `samples` (renders of one frame at stratified times over the shutter, all of
/// one size and with the same planes): colour and alpha are plain means; each depth plane is
/// the alpha-weighted mean of the samples' depths where they saw something (`inf` where none
/// did), so a moving surface's depth is where it was while it covered the pixel. A single
/// sample is returned unchanged.
///
/// ```
/// use nerfx_core::composite::{rgba_planes, shutter_average, rgba_pixels};
/// let a = rgba_planes(1, 1, &[[0.8, 0.0, 0.0, 1.0]]).unwrap();
/// let b = rgba_planes(1, 1, &[[0.0, 0.0, 0.0, 0.0]]).unwrap();
/// let mean = shutter_average(vec![a, b]).unwrap();
/// assert_eq!(rgba_pixels(&mean), vec![[0.4, 0.0, 0.0, 0.5]]);
/// ```
pub fn shutter_average(samples: Vec<Planes>) -> Result<Planes> {
    let n = samples.len();
    let mut samples = samples.into_iter();
    let Some(first) = samples.next() else {
        return Err(Error::invalid("shutter average", "no samples"));
    };
    if n == 1 {
        return Ok(first);
    }
    let rest: Vec<Planes> = samples.collect();
    let same_shape = |p: &Planes| {
        p.width == first.width
            && p.height == first.height
            && p.rgb.is_some() == first.rgb.is_some()
            && p.alpha.is_some() == first.alpha.is_some()
            && p.depth_z.is_some() == first.depth_z.is_some()
            && p.depth_ray.is_some() == first.depth_ray.is_some()
            && p.depth_median.is_some() == first.depth_median.is_some()
    };
    if !rest.iter().all(same_shape) {
        return Err(Error::invalid(
            "shutter average",
            "the samples differ in size or planes",
        ));
    }
    let all: Vec<&Planes> = std::iter::once(&first).chain(&rest).collect();
    let len = first.width as usize * first.height as usize;
    let inv = 1.0 / n as f32;
    let mean = |get: &dyn Fn(&Planes) -> &Plane| {
        let mut out = Plane::filled(first.width, first.height, 0.0);
        for p in &all {
            for (o, v) in out.data.iter_mut().zip(&get(p).data) {
                *o += finite(*v) * inv;
            }
        }
        out
    };
    // Depth weights: each sample's alpha where it has one, else 1 where it saw something.
    let weight = |p: &Planes, i: usize| p.alpha.as_ref().map_or(1.0, |a| finite(a.data[i]));
    let weighted_depth = |get: &dyn Fn(&Planes) -> Option<&Plane>| {
        get(&first)?;
        let mut out = Plane::filled(first.width, first.height, f32::INFINITY);
        for i in 0..len {
            let (mut sum, mut total) = (0.0f64, 0.0f64);
            for p in &all {
                let z = get(p).map_or(f32::INFINITY, |d| depth(d.data[i]));
                let w = weight(p, i);
                if z.is_finite() && w > 0.0 {
                    sum += f64::from(w) * f64::from(z);
                    total += f64::from(w);
                }
            }
            if total > 0.0 {
                out.data[i] = (sum / total) as f32;
            }
        }
        Some(out)
    };
    Ok(Planes {
        width: first.width,
        height: first.height,
        rgb: first.rgb.as_ref().map(|_| {
            [0, 1, 2].map(|c| mean(&|p: &Planes| &p.rgb.as_ref().expect("same shape")[c]))
        }),
        alpha: first
            .alpha
            .as_ref()
            .map(|_| mean(&|p: &Planes| p.alpha.as_ref().expect("same shape"))),
        depth_z: weighted_depth(&|p: &Planes| p.depth_z.as_ref()),
        depth_ray: weighted_depth(&|p: &Planes| p.depth_ray.as_ref()),
        depth_median: weighted_depth(&|p: &Planes| p.depth_median.as_ref()),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn planes(rgba: [f32; 4], z: f32) -> Planes {
        let one = |v: f32| Plane::filled(1, 1, v);
        Planes {
            width: 1,
            height: 1,
            rgb: Some([one(rgba[0]), one(rgba[1]), one(rgba[2])]),
            alpha: Some(one(rgba[3])),
            depth_z: Some(one(z)),
            depth_ray: None,
            depth_median: None,
        }
    }

    #[test]
    fn depth_is_weighted_by_coverage_and_misses_do_not_count() {
        let mean = shutter_average(vec![
            planes([0.5, 0.5, 0.5, 0.5], 2.0),
            planes([1.0, 1.0, 1.0, 1.0], 5.0),
            planes([0.0; 4], f32::INFINITY),
            planes([0.0; 4], 1e10),
        ])
        .unwrap();
        assert_eq!(mean.alpha.unwrap().data, vec![0.375]);
        // (0.5·2 + 1·5) / 1.5 = 4.
        assert_eq!(mean.depth_z.unwrap().data, vec![4.0]);
        let empty = shutter_average(vec![planes([0.0; 4], f32::INFINITY); 3]).unwrap();
        assert_eq!(empty.depth_z.unwrap().data, vec![f32::INFINITY]);
    }

    #[test]
    fn mismatched_samples_are_refused() {
        let mut other = planes([0.0; 4], 1.0);
        other.depth_z = None;
        assert!(shutter_average(vec![planes([0.0; 4], 1.0), other]).is_err());
        assert!(shutter_average(Vec::new()).is_err());
    }
}
