//! What a sampler gives the march besides pieces: fragments.

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
