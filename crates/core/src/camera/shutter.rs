//! Motion blur: when the shutter is open, and at which times a frame is sampled.
//!
//! Blender's `render.motion_blur_shutter` is the time the shutter stays open, in frames, and
//! `render.motion_blur_position` says where frame `f` sits in it: at the opening (`START`),
//! the middle (`CENTER`) or the closing (`END`). A blurred frame is the average over that
//! interval; nerfx samples it at `n` stratified times, the midpoints of `n` equal strata,
//! which integrates a motion that is linear over the shutter with no error and converges as
//! `1/n²` for smooth ones.

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// The longest shutter accepted, in frames (Blender's own limit).
pub const MAX_SHUTTER: f64 = 500.0;

/// Most times a frame may be rendered at over its shutter (`--shutter-samples`, the NeRF
/// Render node's Shutter Samples).
pub const MAX_SHUTTER_SAMPLES: u32 = 1024;

/// Where the frame sits in the shutter interval.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ShutterPosition {
    /// The shutter opens at the frame.
    Start,
    /// The frame is the middle of the shutter interval (Blender's default).
    Center,
    /// The shutter closes at the frame.
    End,
}

/// A shot's motion blur, as Blender's render settings give it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotionBlur {
    /// Shutter time in frames (0 to [`MAX_SHUTTER`]; 0: no blur).
    pub shutter: f64,
    /// Where the frame sits in the shutter interval.
    pub position: ShutterPosition,
}

impl MotionBlur {
    /// Checks the shutter time, naming `what` in the error.
    pub fn validate(&self, what: &str) -> Result<()> {
        if !(0.0..=MAX_SHUTTER).contains(&self.shutter) {
            return Err(Error::invalid(
                what,
                format!(
                    "shutter {} frames; expected 0 to {MAX_SHUTTER}",
                    self.shutter
                ),
            ));
        }
        Ok(())
    }

    /// The times at which `frame` is sampled with `samples` samples: the midpoints of
    /// `samples` equal strata of the shutter interval. One time, `frame` itself, when the
    /// shutter is closed (0) or one sample is asked for.
    ///
    /// ```
    /// use nerfx_core::camera::{MotionBlur, ShutterPosition};
    /// let blur = MotionBlur { shutter: 0.5, position: ShutterPosition::Center };
    /// assert_eq!(blur.times(10.0, 2), vec![9.875, 10.125]);
    /// let start = MotionBlur { position: ShutterPosition::Start, ..blur };
    /// assert_eq!(start.times(10.0, 4), vec![10.0625, 10.1875, 10.3125, 10.4375]);
    /// assert_eq!(MotionBlur { shutter: 0.0, ..blur }.times(10.0, 8), vec![10.0]);
    /// ```
    pub fn times(&self, frame: f64, samples: u32) -> Vec<f64> {
        if self.shutter <= 0.0 || samples <= 1 {
            return vec![frame];
        }
        let open = frame
            - self.shutter
                * match self.position {
                    ShutterPosition::Start => 0.0,
                    ShutterPosition::Center => 0.5,
                    ShutterPosition::End => 1.0,
                };
        let n = f64::from(samples);
        (0..samples)
            .map(|k| open + self.shutter * (f64::from(k) + 0.5) / n)
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strata_cover_the_shutter_evenly() {
        let blur = MotionBlur {
            shutter: 1.5,
            position: ShutterPosition::End,
        };
        let t = blur.times(20.0, 6);
        assert_eq!(t.len(), 6);
        // Midpoints of [18.5, 20] in 6 strata of 0.25.
        for (k, &tk) in t.iter().enumerate() {
            assert!((tk - (18.5 + 0.25 * (k as f64 + 0.5))).abs() < 1e-12);
        }
        // Their mean is the interval's middle.
        let mean: f64 = t.iter().sum::<f64>() / 6.0;
        assert!((mean - 19.25).abs() < 1e-12);
    }

    #[test]
    fn absurd_shutters_are_refused() {
        for shutter in [-0.1, f64::NAN, f64::INFINITY, 1e6] {
            let blur = MotionBlur {
                shutter,
                position: ShutterPosition::Center,
            };
            assert!(blur.validate("motion_blur").is_err(), "{shutter}");
        }
    }
}
