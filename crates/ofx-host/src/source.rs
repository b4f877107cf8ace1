//! What feeds an input clip of an instance: a size and a function rendering any window of it.

use std::sync::Arc;

use nerfx_core::error::{Error, Result};
use nerfx_core::image::{Planes, Window};

/// Renders a window of an input: `(time, window, render_scale)` → planes of the window's
/// size, in the core's raster convention (window at the render scale, `y` down).
pub type SourceFn = dyn Fn(f64, Window, f64) -> Result<Planes> + Send + Sync;

/// What feeds an input clip.
#[derive(Clone)]
pub struct ClipSource {
    /// The source's region of definition `(width, height)` in full-resolution pixels.
    pub rod: (u32, u32),
    /// Its pixels.
    pub render: Arc<SourceFn>,
}

impl ClipSource {
    /// A source of size `rod` rendering through `render`.
    pub fn new(
        rod: (u32, u32),
        render: impl Fn(f64, Window, f64) -> Result<Planes> + Send + Sync + 'static,
    ) -> Self {
        ClipSource {
            rod,
            render: Arc::new(render),
        }
    }

    /// A source that is a fixed full-resolution image, the same at every time; it serves
    /// render scale 1 only.
    pub fn image(planes: Planes) -> Self {
        let rod = (planes.width, planes.height);
        ClipSource::new(rod, move |_, w, s| {
            if s != 1.0 {
                return Err(Error::Unsupported(format!(
                    "a fixed image at render scale {s}"
                )));
            }
            planes.crop(w)
        })
    }
}
