//! SplitMix64 (Steele, Lea, Flood 2014): the one tiny, well-mixed seeded generator of the
//! tests, so every "random" scene, ray and pixel is the same on every run and machine.
//! Each test crate uses a different part of it.
#![allow(dead_code)]

use glam::{DQuat, DVec3, Vec3};

/// The library's generator (the benchmark scenes are drawn from it too), with the draws the
/// tests need.
pub struct SplitMix64(nerfx_core::SplitMix64);

impl SplitMix64 {
    pub fn new(seed: u64) -> Self {
        SplitMix64(nerfx_core::SplitMix64::new(seed))
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0.next_u64()
    }

    /// Uniform in `[lo, hi)`.
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        let u = (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
        lo + (hi - lo) * u
    }

    /// Uniform in `[0, 1)`, single precision.
    pub fn unit(&mut self) -> f32 {
        self.0.unit()
    }

    /// Uniform in `[lo, hi)`, single precision.
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        self.0.range(lo, hi)
    }

    /// Log-uniform in `[lo, hi)`.
    pub fn log_uniform(&mut self, lo: f64, hi: f64) -> f64 {
        self.uniform(lo.ln(), hi.ln()).exp()
    }

    /// Uniform in `0..n`.
    pub fn below(&mut self, n: u64) -> u64 {
        self.next_u64() % n
    }

    /// Each coordinate uniform in `[lo, hi)`.
    pub fn vec(&mut self, lo: f32, hi: f32) -> Vec3 {
        Vec3::new(self.range(lo, hi), self.range(lo, hi), self.range(lo, hi))
    }

    pub fn vec3(&mut self, lo: f64, hi: f64) -> Vec3 {
        self.dvec3(lo, hi).as_vec3()
    }

    pub fn dvec3(&mut self, lo: f64, hi: f64) -> DVec3 {
        DVec3::new(
            self.uniform(lo, hi),
            self.uniform(lo, hi),
            self.uniform(lo, hi),
        )
    }

    /// A uniformly distributed unit vector (rejection from the cube).
    pub fn dir(&mut self) -> Vec3 {
        loop {
            let v = self.vec(-1.0, 1.0);
            let l = v.length();
            if l > 0.1 && l <= 1.0 {
                return v / l;
            }
        }
    }

    /// A rotation about a random axis by a random angle.
    pub fn rotation(&mut self) -> DQuat {
        let axis = loop {
            let a = self.dvec3(-1.0, 1.0);
            if a.length() > 0.1 {
                break a.normalize();
            }
        };
        DQuat::from_axis_angle(axis, self.uniform(0.0, std::f64::consts::TAU))
    }
}
