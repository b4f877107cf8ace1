//! Files the nodes read, loaded once and shared across instances and frames.
//!
//! An entry is keyed by path and checked against the file's size and modification time on
//! every use, so an artist who re-exports a field or shot sees it on the next render without
//! restarting the host. [`purge_caches`] drops everything (the plugin's `purgeCaches`).
//! Loading happens under the cache's lock: two renders asking for the same new file load it
//! once.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::SystemTime;

use nerfx_core::camera::read_shot;
use nerfx_core::camera::Shot;
use nerfx_core::error::{Error, Result};
use nerfx_core::scene::{LoadedScene, SceneDesc};

/// Objects of a nerfstudio `camera_path.json` read as a shot are bound to this name (the
/// scene file binds its instances to it with `"object": "NeRF"`).
pub const CAMERA_PATH_OBJECT: &str = "NeRF";

struct Entry<T> {
    path: PathBuf,
    size: u64,
    modified: SystemTime,
    value: Arc<T>,
}

/// Loaded files keyed by (path, size, modification time).
pub struct FileCache<T> {
    entries: Mutex<Vec<Entry<T>>>,
}

impl<T> Default for FileCache<T> {
    fn default() -> Self {
        Self::new()
    }
}

impl<T> FileCache<T> {
    /// An empty cache.
    pub const fn new() -> Self {
        FileCache {
            entries: Mutex::new(Vec::new()),
        }
    }

    /// The file at `path`, loaded by `load` unless an entry with the same size and
    /// modification time is cached.
    pub fn get(&self, path: &Path, load: impl FnOnce(&Path) -> Result<T>) -> Result<Arc<T>> {
        let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
        let modified = meta.modified().map_err(|e| Error::io(path, e))?;
        let size = meta.len();
        let mut entries = self.entries.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(e) = entries.iter().find(|e| e.path == path) {
            if e.size == size && e.modified == modified {
                return Ok(e.value.clone());
            }
        }
        let value = Arc::new(load(path)?);
        entries.retain(|e| e.path != path);
        entries.push(Entry {
            path: path.to_path_buf(),
            size,
            modified,
            value: value.clone(),
        });
        Ok(value)
    }

    /// Drops every entry (values still in use stay alive with their users).
    pub fn purge(&self) {
        self.entries
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clear();
    }

    /// How many files are cached.
    pub fn len(&self) -> usize {
        self.entries
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .len()
    }

    /// Whether nothing is cached.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

static SCENES: FileCache<LoadedScene> = FileCache::new();
static SHOTS: FileCache<Shot> = FileCache::new();

/// The scene at `path` (a scene file, or one field or splat file: see
/// [`SceneDesc::for_path`]), loaded once while it is unchanged.
pub fn cached_scene(path: &Path) -> Result<Arc<LoadedScene>> {
    SCENES.get(path, |p| SceneDesc::for_path(p)?.load())
}

/// The shot file (or nerfstudio camera path, objects bound to [`CAMERA_PATH_OBJECT`]) at
/// `path`, read once while it is unchanged.
pub fn cached_shot(path: &Path) -> Result<Arc<Shot>> {
    SHOTS.get(path, |p| read_shot(p, CAMERA_PATH_OBJECT))
}

/// Drops every cached scene, shot and shared render.
pub fn purge_caches() {
    SCENES.purge();
    SHOTS.purge();
    super::shared_renders::purge_shared_renders();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reloads_when_the_file_changes() {
        let dir = std::env::temp_dir().join(format!("nerfx-cache-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("n.txt");
        std::fs::write(&path, "1").unwrap();
        let cache: FileCache<String> = FileCache::new();
        let read = |p: &Path| std::fs::read_to_string(p).map_err(|e| Error::io(p, e));
        let first = cache.get(&path, read).unwrap();
        assert!(Arc::ptr_eq(&first, &cache.get(&path, read).unwrap()));
        std::fs::write(&path, "22").unwrap();
        assert_eq!(*cache.get(&path, read).unwrap(), "22");
        assert_eq!(cache.len(), 1);
        cache.purge();
        assert!(cache.is_empty());
        assert!(cache.get(&dir.join("missing"), read).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
