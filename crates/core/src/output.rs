//! Writing an output file without harm to anything but the output asked for, and without
//! destroying what stands there when the write fails.
//!
//! What stands at the output path decides how it is written:
//! - nothing, or a regular file: the bytes go to a temporary file beside it, which replaces
//!   the path by a rename only once complete and flushed to disk. An existing file's
//!   permissions (and its owner and group, where the process may set them) carry over. The
//!   path gets a new inode: other hard links to the old file keep the old bytes.
//! - a symbolic link: it is followed (through every link in a chain) and its target is
//!   replaced as above, beside the target; the link stays a link.
//! - a character device or a FIFO (`/dev/null` for a timing run, a pipe to another program):
//!   written directly, never replaced. The bytes are assembled in a temporary file in the
//!   system's temp folder first, so a failed render writes nothing to it.
//! - a block device, a socket or a folder: refused, naming what is there.
//!
//! A folder that does not allow the temporary file to be created is reported by name: the
//! output may itself be writable, but it cannot be replaced atomically there.

use std::fs::{self, File, OpenOptions};
use std::io;
use std::os::unix::fs::{FileTypeExt, MetadataExt, OpenOptionsExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::{Error, Result};

/// Symbolic links followed before a chain is taken for a loop (Linux's own limit).
const MAX_LINKS: usize = 40;

/// Writes `bytes` to `path` as the module describes.
pub fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    replace_file(path, |temp| {
        fs::write(temp, bytes).map_err(|e| Error::io(path, e))
    })
}

/// Runs `write` on a fresh temporary path and puts the result at `path` as the module
/// describes. When `write` fails (or anything after it does), the temporary file is removed
/// and `path` is left as it was.
pub(crate) fn replace_file(path: &Path, write: impl FnOnce(&Path) -> Result<()>) -> Result<()> {
    let target = resolve_links(path)?;
    let existing = match fs::metadata(&target) {
        Ok(meta) => Some(meta),
        Err(e) if e.kind() == io::ErrorKind::NotFound => None,
        Err(e) => return Err(Error::io(&target, e)),
    };
    let kind = existing.as_ref().map(|m| m.file_type());
    match kind {
        None => replace_regular(path, &target, None, write),
        Some(t) if t.is_file() => replace_regular(path, &target, existing.as_ref(), write),
        Some(t) if t.is_char_device() || t.is_fifo() => write_through(path, &target, write),
        Some(t) => Err(Error::invalid(
            format!("output {}", path.display()),
            format!(
                "{} is {}, not a file nerfx may write",
                target.display(),
                describe(t)
            ),
        )),
    }
}

/// What a file type is, in words, for the refusal.
fn describe(t: fs::FileType) -> &'static str {
    if t.is_dir() {
        "a folder"
    } else if t.is_block_device() {
        "a block device"
    } else if t.is_socket() {
        "a socket"
    } else {
        "neither a regular file, a character device nor a FIFO"
    }
}

/// The path a chain of symbolic links at `path` ends at (`path` itself when it is no link).
/// The end may not exist yet: a dangling link names the file to create.
fn resolve_links(path: &Path) -> Result<PathBuf> {
    let mut current = path.to_path_buf();
    for _ in 0..MAX_LINKS {
        match fs::symlink_metadata(&current) {
            Ok(meta) if meta.file_type().is_symlink() => {
                let link = fs::read_link(&current).map_err(|e| Error::io(&current, e))?;
                current = match current.parent() {
                    Some(dir) if link.is_relative() => dir.join(link),
                    _ => link,
                };
            }
            Ok(_) => return Ok(current),
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(current),
            Err(e) => return Err(Error::io(&current, e)),
        }
    }
    Err(Error::invalid(
        format!("output {}", path.display()),
        format!("more than {MAX_LINKS} symbolic links in a chain (a loop?)"),
    ))
}

/// Writes through a temporary file beside `target` and renames it over `target`, carrying an
/// existing file's permissions and owner.
fn replace_regular(
    path: &Path,
    target: &Path,
    existing: Option<&fs::Metadata>,
    write: impl FnOnce(&Path) -> Result<()>,
) -> Result<()> {
    let dir = match target.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let temp = create_temporary(&dir, target, path)?;
    let result = write(&temp)
        .and_then(|()| {
            if let Some(meta) = existing {
                keep_ownership(&temp, meta, path)?;
            }
            sync(&temp, path)
        })
        .and_then(|()| fs::rename(&temp, target).map_err(|e| Error::io(path, e)));
    if result.is_err() {
        let _ = fs::remove_file(&temp);
    }
    result
}

/// Assembles the output in the system's temp folder, then copies it into the device or FIFO
/// at `target` without replacing it.
fn write_through(
    path: &Path,
    target: &Path,
    write: impl FnOnce(&Path) -> Result<()>,
) -> Result<()> {
    let temp = create_temporary(&std::env::temp_dir(), target, path)?;
    let result = write(&temp).and_then(|()| {
        let mut from = File::open(&temp).map_err(|e| Error::io(&temp, e))?;
        let mut to = OpenOptions::new()
            .write(true)
            .open(target)
            .map_err(|e| Error::io(path, e))?;
        io::copy(&mut from, &mut to).map_err(|e| Error::io(path, e))?;
        Ok(())
    });
    let _ = fs::remove_file(&temp);
    result
}

/// Creates an empty temporary file in `dir` named after `target` (`.<name>.<pid>.<n>.partial`),
/// unique across processes and threads. A folder that is missing or refuses it is named in
/// the I/O error, which keeps the cause's kind.
fn create_temporary(dir: &Path, target: &Path, path: &Path) -> Result<PathBuf> {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let name = target
        .file_name()
        .map_or_else(|| "output".into(), |n| n.to_string_lossy().into_owned());
    loop {
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let temp = dir.join(format!(".{name}.{}.{n}.partial", std::process::id()));
        match OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(0o666)
            .open(&temp)
        {
            Ok(_) => return Ok(temp),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
            Err(e) if e.kind() == io::ErrorKind::NotFound => {
                let why = format!("folder {} does not exist", dir.display());
                return Err(Error::io(path, io::Error::new(e.kind(), why)));
            }
            Err(e) if e.kind() == io::ErrorKind::PermissionDenied => {
                let why = format!(
                    "folder {} is not writable: nerfx writes a temporary file beside the \
                     output and renames it into place, so the folder must allow new files \
                     (the output file's own permissions are not enough)",
                    dir.display()
                );
                return Err(Error::io(path, io::Error::new(e.kind(), why)));
            }
            Err(e) => return Err(Error::io(dir, e)),
        }
    }
}

/// Removes the temporary files an earlier writer of `path` left beside it when it was killed
/// before renaming one into place (`.<name>.<pid>.<n>.partial`, whichever process made them),
/// and returns how many. Only for a caller that alone writes `path` now: a farm task owns the
/// frames of its chunk, so what another process left there is a dead attempt's.
pub fn remove_stale_temporaries(path: &Path) -> Result<usize> {
    let target = resolve_links(path)?;
    let (Some(dir), Some(name)) = (target.parent(), target.file_name()) else {
        return Ok(0);
    };
    let dir = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    let prefix = format!(".{}.", name.to_string_lossy());
    let entries = match fs::read_dir(dir) {
        Ok(entries) => entries,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(0),
        Err(e) => return Err(Error::io(dir, e)),
    };
    let mut removed = 0;
    for entry in entries {
        let entry = entry.map_err(|e| Error::io(dir, e))?;
        let file = entry.file_name().to_string_lossy().into_owned();
        let Some(middle) = file
            .strip_prefix(&prefix)
            .and_then(|rest| rest.strip_suffix(".partial"))
        else {
            continue;
        };
        // `<pid>.<n>`: two numbers, so an output merely named like a temporary is kept.
        let numbered = middle
            .split_once('.')
            .is_some_and(|(pid, n)| [pid, n].iter().all(|s| s.parse::<u64>().is_ok()));
        if numbered && fs::remove_file(entry.path()).is_ok() {
            removed += 1;
        }
    }
    Ok(removed)
}

/// Gives `temp` the permissions of the file it replaces, and its owner and group where the
/// process may (root may; others may keep their group at most).
fn keep_ownership(temp: &Path, meta: &fs::Metadata, path: &Path) -> Result<()> {
    let mode = meta.permissions().mode() & 0o7777;
    let current = fs::metadata(temp).map_err(|e| Error::io(temp, e))?;
    if current.uid() != meta.uid() || current.gid() != meta.gid() {
        // Refused without privilege: the new file then keeps the writer's own ids.
        let _ = std::os::unix::fs::chown(temp, Some(meta.uid()), Some(meta.gid()));
    }
    // After chown, which clears set-id bits.
    fs::set_permissions(temp, fs::Permissions::from_mode(mode)).map_err(|e| Error::io(path, e))
}

/// Flushes the finished temporary file to disk, so a crash after the rename cannot leave an
/// empty or partial file under the output's name.
fn sync(temp: &Path, path: &Path) -> Result<()> {
    File::open(temp)
        .and_then(|f| f.sync_all())
        .map_err(|e| Error::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::symlink;
    use std::process::Command;

    fn good(bytes: &'static [u8]) -> impl FnOnce(&Path) -> Result<()> {
        move |temp| fs::write(temp, bytes).map_err(|e| Error::io(temp, e))
    }

    fn names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    /// Whether this process may create device nodes (root); device tests need it.
    fn can_mknod(dir: &Path) -> bool {
        let probe = dir.join("probe");
        let ok = Command::new("mknod")
            .arg(&probe)
            .args(["c", "1", "3"])
            .status()
            .is_ok_and(|s| s.success());
        let _ = fs::remove_file(&probe);
        ok
    }

    #[test]
    fn stale_temporaries_of_the_output_are_removed_and_nothing_else() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("frame.0001.exr");
        for name in [
            ".frame.0001.exr.4242.0.partial",
            ".frame.0001.exr.7.12.partial",
            ".frame.0002.exr.4242.0.partial",
            ".frame.0001.exr.notes.partial",
            "frame.0001.exr",
        ] {
            fs::write(dir.path().join(name), b"x").unwrap();
        }
        assert_eq!(remove_stale_temporaries(&path).unwrap(), 2);
        assert_eq!(
            names(dir.path()),
            [
                ".frame.0001.exr.notes.partial",
                ".frame.0002.exr.4242.0.partial",
                "frame.0001.exr"
            ]
        );
        let missing = dir.path().join("no-such-folder/frame.exr");
        assert_eq!(remove_stale_temporaries(&missing).unwrap(), 0);
    }

    #[test]
    fn a_failed_write_leaves_the_old_file_and_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("frame.exr");
        fs::write(&path, b"the good frame").unwrap();
        let err = replace_file(&path, |temp| {
            fs::write(temp, b"half a fr").unwrap();
            Err(Error::invalid("frame", "failed half way"))
        });
        assert!(err.is_err());
        assert_eq!(fs::read(&path).unwrap(), b"the good frame");
        assert_eq!(names(dir.path()), ["frame.exr"]);
        replace_file(&path, good(b"the new frame")).unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"the new frame");
        assert_eq!(names(dir.path()), ["frame.exr"]);
    }

    #[test]
    fn a_new_file_is_created_and_an_existing_file_keeps_its_mode() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("new.exr");
        write_file(&path, b"one").unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"one");
        fs::set_permissions(&path, fs::Permissions::from_mode(0o600)).unwrap();
        write_file(&path, b"two").unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"two");
        let mode = fs::metadata(&path).unwrap().permissions().mode() & 0o7777;
        assert_eq!(mode, 0o600);
        fs::set_permissions(&path, fs::Permissions::from_mode(0o640)).unwrap();
        write_file(&path, b"three").unwrap();
        let mode = fs::metadata(&path).unwrap().permissions().mode() & 0o7777;
        assert_eq!(mode, 0o640);
    }

    #[test]
    fn a_symlink_stays_a_link_and_its_target_is_replaced_beside_it() {
        let dir = tempfile::tempdir().unwrap();
        let shots = dir.path().join("shots");
        fs::create_dir(&shots).unwrap();
        let real = shots.join("real.exr");
        fs::write(&real, b"old").unwrap();
        let link = dir.path().join("link.exr");
        symlink("shots/real.exr", &link).unwrap();
        // A chain: a link to the link.
        let chain = dir.path().join("chain.exr");
        symlink(&link, &chain).unwrap();
        write_file(&chain, b"new").unwrap();
        assert!(fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        assert!(fs::symlink_metadata(&chain)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(fs::read(&real).unwrap(), b"new");
        assert_eq!(names(&shots), ["real.exr"]);
        // A dangling link names the file to create.
        let dangling = dir.path().join("dangling.exr");
        symlink("shots/later.exr", &dangling).unwrap();
        write_file(&dangling, b"later").unwrap();
        assert!(fs::symlink_metadata(&dangling)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(fs::read(shots.join("later.exr")).unwrap(), b"later");
    }

    #[test]
    fn a_symlink_loop_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("a.exr");
        let b = dir.path().join("b.exr");
        symlink(&b, &a).unwrap();
        symlink(&a, &b).unwrap();
        let err = write_file(&a, b"x").unwrap_err().to_string();
        assert!(err.contains("symbolic links"), "{err}");
        assert_eq!(names(dir.path()), ["a.exr", "b.exr"]);
    }

    #[test]
    fn a_fifo_is_written_through_not_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("pipe");
        assert!(Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .unwrap()
            .success());
        let reader = {
            let fifo = fifo.clone();
            std::thread::spawn(move || fs::read(fifo).unwrap())
        };
        write_file(&fifo, b"through the pipe").unwrap();
        assert_eq!(reader.join().unwrap(), b"through the pipe");
        assert!(fs::symlink_metadata(&fifo).unwrap().file_type().is_fifo());
        assert_eq!(names(dir.path()), ["pipe"]);
    }

    #[test]
    fn character_devices_are_written_through_and_block_devices_refused() {
        let dir = tempfile::tempdir().unwrap();
        if !can_mknod(dir.path()) {
            eprintln!("skipped: creating device nodes needs root");
            return;
        }
        // A null device and a full device of this folder's own, never the machine's /dev.
        let null = dir.path().join("null");
        let full = dir.path().join("full");
        let block = dir.path().join("loop");
        for (node, kind, major, minor) in [
            (&null, "c", "1", "3"),
            (&full, "c", "1", "7"),
            (&block, "b", "7", "0"),
        ] {
            let made = Command::new("mknod")
                .arg(node)
                .args([kind, major, minor])
                .status();
            assert!(made.unwrap().success());
        }
        write_file(&null, b"discarded").unwrap();
        assert!(fs::symlink_metadata(&null)
            .unwrap()
            .file_type()
            .is_char_device());

        let err = write_file(&full, b"no room").unwrap_err().to_string();
        assert!(err.contains("full"), "{err}");
        assert!(fs::symlink_metadata(&full)
            .unwrap()
            .file_type()
            .is_char_device());

        let err = write_file(&block, b"never").unwrap_err().to_string();
        assert!(err.contains("block device"), "{err}");
        assert!(fs::symlink_metadata(&block)
            .unwrap()
            .file_type()
            .is_block_device());
        assert_eq!(names(dir.path()), ["full", "loop", "null"]);
    }

    #[test]
    fn sockets_and_folders_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let socket = dir.path().join("sock");
        let _listener = std::os::unix::net::UnixListener::bind(&socket).unwrap();
        let err = write_file(&socket, b"x").unwrap_err().to_string();
        assert!(err.contains("socket"), "{err}");
        assert!(fs::symlink_metadata(&socket)
            .unwrap()
            .file_type()
            .is_socket());
        let folder = dir.path().join("folder");
        fs::create_dir(&folder).unwrap();
        let err = write_file(&folder, b"x").unwrap_err().to_string();
        assert!(err.contains("a folder"), "{err}");
    }

    #[test]
    fn a_missing_folder_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("no/such/frame.exr");
        let err = write_file(&path, b"x").unwrap_err().to_string();
        assert!(
            err.contains("does not exist") && err.contains("no/such"),
            "{err}"
        );
    }
}
