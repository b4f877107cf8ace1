//! Field throughput: samples per second of a [`Field`]'s batched queries, as the marcher
//! issues them (batches of [`BATCH`] points, one batch per task, on a pool of a given size).
//!
//! Three figures per run, each counting the samples of the whole set, occupied or not:
//! `density` alone (what the marcher asks of every sample); the marcher's route for a
//! sample that is also shaded, `density_with_features` then `radiance_with_features` (the
//! colour query reuses the density pass's encoding and network outputs); and `density`
//! then `radiance` (standalone queries: a trained field encodes each point twice).
//!
//! Rates are per second of the process's CPU time (user + system, all threads) where the
//! system says it (Linux `/proc/self/stat`), else per second of wall time: on a machine
//! shared with other work the CPU time is the steadier figure, and `threads` times the
//! rate per CPU second is what that many uncontended cores would give.

use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

use nerfx_core::error::{Error, Result};
use nerfx_core::field::Field;

/// Points per query (the marcher's order of magnitude).
pub const BATCH: usize = 1024;

/// Samples per second of one configuration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Throughput {
    /// Whether the rates are per CPU second (else per wall second).
    pub per_cpu_second: bool,
    /// `density` alone.
    pub density: f64,
    /// `density_with_features` then `radiance_with_features` on each batch (as renders).
    pub shaded: f64,
    /// `density` then `radiance` on each batch.
    pub density_radiance: f64,
    /// The `shaded` route per second of wall time, all threads together: what the
    /// machine delivered (on a quiet machine, `threads` cores' worth).
    pub shaded_wall: f64,
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
    let stride = field.feature_count();
    let rate = |route: Route| {
        let pass = || {
            pool.install(|| {
                points
                    .par_chunks(BATCH)
                    .zip(dirs.par_chunks(BATCH))
                    .for_each_init(
                        || {
                            (
                                vec![0.0f32; BATCH],
                                vec![Vec3::ZERO; BATCH],
                                vec![0.0f32; BATCH * stride],
                            )
                        },
                        |(sigma, rgb, features), (p, d)| {
                            let (sigma, rgb) = (&mut sigma[..p.len()], &mut rgb[..p.len()]);
                            match route {
                                Route::Density => field.density(p, sigma),
                                Route::Shaded => {
                                    let f = &mut features[..p.len() * stride];
                                    field.density_with_features(p, sigma, f);
                                    field.radiance_with_features(p, d, f, rgb);
                                }
                                Route::Twice => {
                                    field.density(p, sigma);
                                    field.radiance(p, d, rgb);
                                }
                            }
                        },
                    )
            })
        };
        pass();
        let (t, cpu) = (Instant::now(), process_cpu_seconds());
        let mut n = 0usize;
        while n == 0 || t.elapsed().as_secs_f64() < seconds {
            pass();
            n += points.len();
        }
        let wall = n as f64 / t.elapsed().as_secs_f64();
        let cpu = cpu.zip(process_cpu_seconds()).map(|(a, b)| b - a);
        match cpu {
            Some(c) if c > 0.0 => (n as f64 / c, wall),
            _ => (wall, wall),
        }
    };
    let per_cpu_second = process_cpu_seconds().is_some();
    let (shaded, shaded_wall) = rate(Route::Shaded);
    Ok(Throughput {
        per_cpu_second,
        density: rate(Route::Density).0,
        shaded,
        density_radiance: rate(Route::Twice).0,
        shaded_wall,
    })
}

/// User + system CPU time of this process so far, all threads (Linux `/proc/self/stat`, in
/// the kernel's fixed 100 Hz `USER_HZ` ticks); `None` where that file is not there.
pub fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // After the command name (which ends at the last ')'), utime and stime are the 12th
    // and 13th fields (14 and 15 of the whole line).
    let rest = &stat[stat.rfind(')')? + 1..];
    let mut fields = rest.split_whitespace().skip(11);
    let user: u64 = fields.next()?.parse().ok()?;
    let system: u64 = fields.next()?.parse().ok()?;
    Some((user + system) as f64 / 100.0)
}

/// Which queries one benchmark pass makes.
#[derive(Clone, Copy)]
enum Route {
    Density,
    Shaded,
    Twice,
}

#[cfg(test)]
mod tests {
    use super::*;
    use nerfx_core::field::{Analytic, Primitive, ShColor, Shape};

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
        assert!(t.density > 0.0 && t.shaded > 0.0 && t.density_radiance > 0.0);
        assert!(throughput(&f, &pts, &pts[..10], 1, 0.0).is_err());
        assert!(throughput(&f, &[], &[], 1, 0.0).is_err());
    }
}
