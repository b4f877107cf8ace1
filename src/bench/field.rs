//! Field throughput: samples per second of a [`Field`]'s batched queries, as the marcher
//! issues them (batches of [`BATCH`] points, one batch per task, on a pool of a given size).
//!
//! Two figures per run: `density` alone (what the marcher asks of every sample) and
//! `density` followed by `radiance` on the same batch (the worst case: every sample also
//! shaded). Both count the samples of the whole set, occupied or not.

use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::field::Field;

/// Points per query (the marcher's order of magnitude).
pub const BATCH: usize = 1024;

/// Samples per second of one configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Throughput {
    /// `density` alone.
    pub density: f64,
    /// `density` then `radiance` on each batch.
    pub density_radiance: f64,
}

/// Measures `field` on `points` (and `dirs`, one per point) with `threads` workers, running
/// each query kind over the whole set repeatedly for at least `seconds` (after one untimed
/// pass that warms the caches).
pub fn throughput<F: Field>(
    field: &F,
    points: &[Vec3],
    dirs: &[Vec3],
    threads: usize,
    seconds: f64,
) -> Result<Throughput> {
    if points.len() != dirs.len() || points.is_empty() {
        return Err(Error::invalid(
            "field benchmark samples",
            format!("{} points and {} directions", points.len(), dirs.len()),
        ));
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads.max(1))
        .build()
        .map_err(|e| Error::invalid("field benchmark threads", e.to_string()))?;
    let rate = |shade: bool| {
        let pass = || {
            pool.install(|| {
                points
                    .par_chunks(BATCH)
                    .zip(dirs.par_chunks(BATCH))
                    .for_each_init(
                        || (vec![0.0f32; BATCH], vec![Vec3::ZERO; BATCH]),
                        |(sigma, rgb), (p, d)| {
                            field.density(p, &mut sigma[..p.len()]);
                            if shade {
                                field.radiance(p, d, &mut rgb[..p.len()]);
                            }
                        },
                    )
            })
        };
        pass();
        let t = Instant::now();
        let mut n = 0usize;
        while n == 0 || t.elapsed().as_secs_f64() < seconds {
            pass();
            n += points.len();
        }
        n as f64 / t.elapsed().as_secs_f64()
    };
    Ok(Throughput {
        density: rate(false),
        density_radiance: rate(true),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::{Analytic, Primitive, ShColor, Shape};

    #[test]
    fn counts_every_sample_and_refuses_mismatched_input() {
        let f = Analytic {
            primitives: vec![Primitive {
                shape: Shape::Sphere {
                    center: Vec3::ZERO,
                    radius: 1.0,
                },
                density: 2.0,
                color: ShColor::constant(Vec3::ONE),
            }],
        };
        let pts = vec![Vec3::ZERO; 3000];
        let t = throughput(&f, &pts, &pts, 1, 0.0).unwrap();
        assert!(t.density > 0.0 && t.density_radiance > 0.0);
        assert!(throughput(&f, &pts, &pts[..10], 1, 0.0).is_err());
        assert!(throughput(&f, &[], &[], 1, 0.0).is_err());
    }
}
