//! Reading the files a user names: regular files only (a directory, a device such as
//! `/dev/zero` or a pipe is refused, naming the file), read whole but never past the size the
//! file had when it was opened, so memory stays bounded by what the file really holds.

use std::io::Read;
use std::path::Path;

use crate::error::{Error, Result};

/// The regular file at `path`, open for reading, and its length when opened (a folder, a
/// device or a pipe is refused, naming the file).
pub(crate) fn open_regular(path: &Path) -> Result<(std::fs::File, u64)> {
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let meta = file.metadata().map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        let what = if meta.is_dir() {
            "a folder"
        } else {
            "not a regular file"
        };
        return Err(Error::format(
            path,
            "",
            format!("is {what}; expected a file"),
        ));
    }
    Ok((file, meta.len()))
}

/// The bytes of the regular file at `path`.
pub(crate) fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    let (file, len) = open_regular(path)?;
    let mut bytes = Vec::with_capacity(usize::try_from(len).unwrap_or(0));
    file.take(len)
        .read_to_end(&mut bytes)
        .map_err(|e| Error::io(path, e))?;
    Ok(bytes)
}

/// The UTF-8 text of the regular file at `path`.
pub fn read_text(path: &Path) -> Result<String> {
    String::from_utf8(read_bytes(path)?).map_err(|e| {
        Error::format(
            path,
            format!("byte {}", e.utf8_error().valid_up_to()),
            "is not UTF-8 text",
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folders_and_devices_are_refused_naming_them() {
        let dir = tempfile::tempdir().unwrap();
        let e = read_bytes(dir.path()).unwrap_err().to_string();
        assert!(e.contains("is a folder"), "{e}");
        let e = read_text(Path::new("/dev/zero")).unwrap_err().to_string();
        assert!(
            e.contains("/dev/zero") && e.contains("not a regular file"),
            "{e}"
        );
        let file = dir.path().join("t.json");
        std::fs::write(&file, [b'{', 0xff, b'}']).unwrap();
        let e = read_text(&file).unwrap_err().to_string();
        assert!(e.contains("byte 1") && e.contains("UTF-8"), "{e}");
        std::fs::write(&file, "{}").unwrap();
        assert_eq!(read_text(&file).unwrap(), "{}");
    }
}
