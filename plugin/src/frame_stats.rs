//! What the renders of the frame on show have counted, for the node's warning.
//!
//! A host renders a frame in tiles, possibly on several threads at once, and a clean tile says
//! nothing about its neighbours: the warning is the frame's. Each instance keeps the
//! statistics of the windows it rendered at one time, render scale and quality; a render of
//! another frame (or scale, or quality) starts afresh, as does an edit of the artist, and a
//! window rendered again replaces its earlier count. What the frame's counts say is reported
//! under the record's lock, so a clean tile that counted before a warned one cannot clear the
//! warning after it was posted.

use std::sync::{Mutex, PoisonError};

use nerfx_core::image::Window;
use nerfx_core::render::RenderStats;

/// Windows kept per frame at most: a viewer panning over one frame asks for ever new windows,
/// and the oldest are forgotten rather than held without bound.
const MAX_WINDOWS: usize = 1024;

/// Which frame a render belongs to: its time, render scale and draft flag, bit for bit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameKey {
    time: u64,
    scale: u64,
    draft: bool,
}

impl FrameKey {
    /// The frame of a render at `time`, `scale` and draft quality or not.
    pub fn new(time: f64, scale: f64, draft: bool) -> Self {
        FrameKey {
            time: time.to_bits(),
            scale: scale.to_bits(),
            draft,
        }
    }
}

#[derive(Debug, Default)]
struct Frame {
    key: Option<FrameKey>,
    windows: Vec<(Window, RenderStats)>,
    /// Connected input clips the host gave no image for, in any window of the frame.
    missing: Vec<&'static str>,
}

/// One instance's record of the frame on show (shared by its render threads).
#[derive(Debug, Default)]
pub struct FrameStats(Mutex<Frame>);

impl FrameStats {
    /// Records what rendering `window` of `frame` counted and which connected inputs had no
    /// image (`missing`), then hands the frame's counts and missing inputs so far to `report`
    /// (still holding the record).
    pub fn record(
        &self,
        frame: FrameKey,
        window: Window,
        stats: RenderStats,
        missing: &[&'static str],
        report: impl FnOnce(&RenderStats, &[&'static str]),
    ) {
        let mut f = self.0.lock().unwrap_or_else(PoisonError::into_inner);
        if f.key != Some(frame) {
            *f = Frame {
                key: Some(frame),
                ..Frame::default()
            };
        }
        for clip in missing {
            if !f.missing.contains(clip) {
                f.missing.push(clip);
            }
        }
        f.windows.retain(|(w, _)| *w != window);
        if f.windows.len() >= MAX_WINDOWS {
            f.windows.remove(0);
        }
        f.windows.push((window, stats));
        let total = f
            .windows
            .iter()
            .fold(RenderStats::default(), |sum, (_, s)| sum + *s);
        report(&total, &f.missing);
    }

    /// Forgets the frame (an edit of the artist: its renders are stale).
    pub fn reset(&self) {
        *self.0.lock().unwrap_or_else(PoisonError::into_inner) = Frame::default();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Records `stats` of `window` into `f`; what it reported for the frame.
    fn record(f: &FrameStats, at: FrameKey, window: Window, stats: RenderStats) -> RenderStats {
        let mut reported = None;
        f.record(at, window, stats, &[], |s, _| reported = Some(*s));
        reported.expect("a report")
    }

    fn stats(pixels: u64, limited: u64) -> RenderStats {
        RenderStats {
            pixels,
            budget_limited_rays: limited,
            ..RenderStats::default()
        }
    }

    #[test]
    fn a_frame_sums_its_tiles_once_each_and_a_new_frame_starts_afresh() {
        let f = FrameStats::default();
        let at = FrameKey::new(1001.0, 1.0, false);
        let (a, b) = (Window::new(0, 0, 8, 8), Window::new(8, 0, 16, 8));
        assert_eq!(record(&f, at, a, stats(64, 3)), stats(64, 3));
        // A clean neighbour keeps the frame's warning.
        assert_eq!(record(&f, at, b, stats(64, 0)), stats(128, 3));
        // The same tile again replaces its count.
        assert_eq!(record(&f, at, a, stats(64, 3)), stats(128, 3));
        // Another frame, scale or quality is another frame.
        for other in [
            FrameKey::new(1002.0, 1.0, false),
            FrameKey::new(1002.0, 0.5, false),
            FrameKey::new(1002.0, 0.5, true),
        ] {
            assert_eq!(record(&f, other, b, stats(64, 0)), stats(64, 0));
        }
        record(&f, at, a, stats(64, 3));
        f.reset();
        assert_eq!(record(&f, at, b, stats(64, 0)), stats(64, 0));
    }

    #[test]
    fn an_input_missing_in_one_window_is_the_frames() {
        let f = FrameStats::default();
        let at = FrameKey::new(1.0, 1.0, false);
        let mut said = Vec::new();
        f.record(
            at,
            Window::new(0, 0, 1, 1),
            stats(1, 0),
            &["Source"],
            |_, m| said = m.to_vec(),
        );
        f.record(at, Window::new(1, 0, 2, 1), stats(1, 0), &[], |_, m| {
            said = m.to_vec()
        });
        assert_eq!(said, ["Source"]);
        f.record(
            FrameKey::new(2.0, 1.0, false),
            Window::new(1, 0, 2, 1),
            stats(1, 0),
            &[],
            |_, m| said = m.to_vec(),
        );
        assert!(said.is_empty());
    }

    #[test]
    fn windows_are_bounded() {
        let f = FrameStats::default();
        let at = FrameKey::new(1.0, 1.0, false);
        record(&f, at, Window::new(0, 0, 1, 1), stats(1, 1));
        let mut last = RenderStats::default();
        for i in 1..=MAX_WINDOWS as u32 {
            last = record(&f, at, Window::new(i, 0, i + 1, 1), stats(1, 0));
        }
        // The first (warned) window was forgotten to make room.
        assert_eq!(last, stats(MAX_WINDOWS as u64, 0));
    }
}
