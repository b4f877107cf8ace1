//! What a sampler gives the march besides pieces: fragments; and the pixel rays a fragment
//! sampler walks in its field's frame.

use crate::camera::Ray;

/// What a sampler gives the march besides pieces: a sample's opacity and colour at one
/// depth (a splat's contribution to a pixel, or a trainer's sample), composited in depth
/// order with the march's pieces and the other fragments.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Fragment {
    /// Distance along the pixel's world ray.
    pub(crate) t: f64,
    /// Opacity.
    pub alpha: f32,
    /// Colour in the trained space (encoded to the scene's composite space).
    pub rgb: [f32; 3],
}

/// A tile's pixel rays in a sampler's own frame: the rays it walks, and per ray the pixel it
/// belongs to and the field units per world unit along it.
pub(crate) struct LocalRays<R> {
    pub rays: Vec<R>,
    pub owners: Vec<(u32, f64)>,
}

impl<R> Default for LocalRays<R> {
    fn default() -> Self {
        LocalRays {
            rays: Vec::new(),
            owners: Vec::new(),
        }
    }
}

impl<R> LocalRays<R> {
    /// Replaces the rays by `local(ray)` of every pixel ray that gives one.
    pub fn collect(&mut self, rays: &[Option<Ray>], local: impl Fn(&Ray) -> Option<(R, f64)>) {
        self.rays.clear();
        self.owners.clear();
        for (i, ray) in rays.iter().enumerate() {
            if let Some((r, k)) = ray.as_ref().and_then(&local) {
                self.rays.push(r);
                self.owners.push((i as u32, k));
            }
        }
    }
}
