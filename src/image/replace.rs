//! Writing an output file so that a failure never destroys the one already there: the bytes go
//! to a temporary file beside it, which replaces the target only once complete.

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// Runs `write` on a temporary path in `path`'s folder and renames the result over `path`.
/// When `write` fails (or the rename does), the temporary file is removed and `path` is left
/// as it was.
pub(crate) fn replace_file(path: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    let temp = temporary_beside(path);
    let result =
        write(&temp).and_then(|()| std::fs::rename(&temp, path).map_err(|e| Error::io(path, e)));
    if result.is_err() {
        let _ = std::fs::remove_file(&temp);
    }
    result
}

/// `.<name>.<pid>.partial` in the same folder (a rename within a folder is atomic).
fn temporary_beside(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map_or_else(|| "output".into(), |n| n.to_string_lossy().into_owned());
    path.with_file_name(format!(".{name}.{}.partial", std::process::id()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_write_leaves_the_old_file_and_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("frame.exr");
        std::fs::write(&path, b"the good frame").unwrap();
        let err = replace_file(&path, |temp| {
            std::fs::write(temp, b"half a fr").unwrap();
            Err(Error::invalid("frame", "failed half way"))
        });
        assert!(err.is_err());
        assert_eq!(std::fs::read(&path).unwrap(), b"the good frame");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        replace_file(&path, |temp| {
            std::fs::write(temp, b"the new frame").map_err(|e| Error::io(temp, e))
        })
        .unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"the new frame");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }
}
