//! Reading the file a shot comes from: a nerfx shot file, or a nerfstudio camera path.

use std::path::Path;

use super::{CameraPath, Shot};
use crate::error::Result;

/// Reads a nerfx shot file, or a nerfstudio `camera_path.json` (recognised by its
/// `camera_path` key) as a shot whose frames count from 0, as `ns-render` numbers them, and
/// whose NeRF object (the scene instances bound to `nerf_object`) is placed so that the
/// field sees each frame's `camera_to_world` exactly (see [`CameraPath::to_shot`]).
pub fn read_shot(path: &Path, nerf_object: &str) -> Result<Shot> {
    let text = crate::input::read_text(path)?;
    // Python's json writes NaN and Infinity: read as null, they still leave the file's kind
    // clear, and the reader of that kind names the element that holds one.
    let is_camera_path = crate::json::parse_json::<serde_json::Value>(&text, path, "a shot")
        .is_ok_and(|v| v.get("camera_path").is_some());
    if is_camera_path {
        CameraPath::from_json_str(&text, path)?.to_shot(0, nerf_object)
    } else {
        Shot::from_json_str(&text, path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_paths_read_as_shots() {
        let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/data");
        let path = data.join("viewer_camera_path_b.json");
        let shot = read_shot(&path, "NeRF").unwrap();
        assert_eq!(shot.frames.len(), 42);
        assert_eq!(shot.frames[0].frame, 0);
        assert!(shot.frame(0).unwrap().object_matrix("NeRF").is_ok());
        let demo = std::env::temp_dir().join(format!("nerfx-frames-{}.json", std::process::id()));
        crate::demo::shot(8, 6).write(&demo).unwrap();
        let back = read_shot(&demo, "NeRF").unwrap();
        std::fs::remove_file(&demo).ok();
        assert_eq!(back.frames.len(), crate::demo::FRAMES as usize);
    }
}
