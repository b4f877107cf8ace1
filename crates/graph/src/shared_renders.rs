//! Renders shared by NeRF Render nodes that differ only in what they output.
//!
//! A compositor asks one field for several passes (RGBA for the comp, depth Z for a depth
//! merge, accumulation for a matte) through several nodes. One march gives them all, so the
//! first node to ask renders every pass and the others take theirs from here: nodes whose
//! scene, shot, time, window, render scale and every parameter that changes the march agree
//! get the same render. The cache holds at most [`BUDGET_BYTES`] of planes, dropping the
//! least recently used first; two threads asking for the same render at once wait for one
//! march; each gets the render's statistics with its planes. Entries hold the scene and shot weakly, so an edited file is never served stale
//! and a replaced scene is not kept alive by the cache.

use std::sync::{Arc, Mutex, PoisonError, Weak};

use super::node::Rendered;
use super::values::ParamValues;
use nerfx_core::camera::Shot;
use nerfx_core::error::Result;
use nerfx_core::image::{Planes, Window};
use nerfx_core::scene::LoadedScene;

/// At most this many bytes of planes are kept (a 1080p frame with every pass is ~58 MB).
const BUDGET_BYTES: usize = 512 << 20;

/// What identifies one render: the loaded files (by identity) and everything that changes
/// the march.
#[derive(Clone, Debug)]
pub(super) struct RenderKey {
    /// The scene as loaded (a reloaded file is another scene).
    pub scene: Weak<LoadedScene>,
    /// The shot as loaded.
    pub shot: Weak<Shot>,
    /// The node's values with those that only pick or grade an output reset to defaults.
    pub values: ParamValues,
    /// The host's time.
    pub time: f64,
    /// The render scale.
    pub render_scale: f64,
    /// The pixels rendered.
    pub window: Window,
    /// The host's draft flag.
    pub draft: bool,
}

impl PartialEq for RenderKey {
    fn eq(&self, other: &Self) -> bool {
        self.scene.ptr_eq(&other.scene)
            && self.shot.ptr_eq(&other.shot)
            && self.time.to_bits() == other.time.to_bits()
            && self.render_scale.to_bits() == other.render_scale.to_bits()
            && self.window == other.window
            && self.draft == other.draft
            && self.values == other.values
    }
}

type Slot = Arc<Mutex<Option<Arc<Rendered>>>>;

struct Entry {
    key: RenderKey,
    slot: Slot,
    bytes: usize,
    used: u64,
}

/// How the cache has served renders since the process started (or the last purge).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SharedRenderStats {
    /// Renders marched.
    pub marched: u64,
    /// Requests served from a render another request marched.
    pub shared: u64,
    /// Bytes of planes held now.
    pub bytes: usize,
}

#[derive(Default)]
struct Cache {
    entries: Vec<Entry>,
    clock: u64,
    marched: u64,
    shared: u64,
}

impl Cache {
    fn bytes(&self) -> usize {
        self.entries.iter().map(|e| e.bytes).sum()
    }

    /// Records a finished render's size, then drops the least recently used finished renders
    /// until the cache fits its budget again (a render larger than the budget is not kept).
    fn finished(&mut self, slot: &Slot, bytes: usize) {
        self.marched += 1;
        if let Some(e) = self.entries.iter_mut().find(|e| Arc::ptr_eq(&e.slot, slot)) {
            e.bytes = bytes;
        }
        while self.bytes() > BUDGET_BYTES {
            let oldest = self
                .entries
                .iter()
                .enumerate()
                .filter(|(_, e)| e.bytes > 0)
                .min_by_key(|(_, e)| e.used)
                .map(|(i, _)| i);
            match oldest {
                Some(i) => drop(self.entries.swap_remove(i)),
                None => break,
            }
        }
    }

    fn forget(&mut self, slot: &Slot) {
        self.entries.retain(|e| !Arc::ptr_eq(&e.slot, slot));
    }
}

static CACHE: Mutex<Option<Cache>> = Mutex::new(None);

fn with_cache<T>(f: impl FnOnce(&mut Cache) -> T) -> T {
    let mut cache = CACHE.lock().unwrap_or_else(PoisonError::into_inner);
    f(cache.get_or_insert_with(Cache::default))
}

fn plane_bytes(p: &Planes) -> usize {
    let planes = p.rgb.as_ref().map_or(0, |_| 3)
        + [&p.alpha, &p.depth_z, &p.depth_ray, &p.depth_median]
            .iter()
            .filter(|p| p.is_some())
            .count();
    planes * p.width as usize * p.height as usize * std::mem::size_of::<f32>()
}

/// The render for `key`: shared if one is cached or being marched, else marched by `march`
/// (a failed march is not cached: the next request tries again).
pub(super) fn shared_render(
    key: RenderKey,
    march: impl FnOnce() -> Result<Rendered>,
) -> Result<Arc<Rendered>> {
    let slot = with_cache(|cache| {
        cache.clock += 1;
        let clock = cache.clock;
        // Entries of scenes or shots no longer loaded can never be asked for again.
        cache
            .entries
            .retain(|e| e.key.scene.strong_count() > 0 && e.key.shot.strong_count() > 0);
        match cache.entries.iter_mut().find(|e| e.key == key) {
            Some(e) => {
                e.used = clock;
                e.slot.clone()
            }
            None => {
                let slot = Slot::default();
                cache.entries.push(Entry {
                    key,
                    slot: slot.clone(),
                    bytes: 0,
                    used: clock,
                });
                slot
            }
        }
    });
    let mut held = slot.lock().unwrap_or_else(PoisonError::into_inner);
    if let Some(r) = &*held {
        with_cache(|cache| cache.shared += 1);
        return Ok(r.clone());
    }
    match march() {
        Ok(r) => {
            let r = Arc::new(r);
            *held = Some(r.clone());
            drop(held);
            with_cache(|cache| cache.finished(&slot, plane_bytes(&r.planes)));
            Ok(r)
        }
        Err(e) => {
            drop(held);
            with_cache(|cache| cache.forget(&slot));
            Err(e)
        }
    }
}

/// How the cache has served renders so far.
pub fn shared_render_stats() -> SharedRenderStats {
    with_cache(|cache| SharedRenderStats {
        marched: cache.marched,
        shared: cache.shared,
        bytes: cache.bytes(),
    })
}

/// Drops every shared render and resets the counts.
pub(super) fn purge_shared_renders() {
    *CACHE.lock().unwrap_or_else(PoisonError::into_inner) = None;
}
