//! Zip archives held in memory: the container of torch checkpoints, read with the `zip` crate.
//!
//! Torch writes its archives with miniz: every entry stored, data aligned to 64 bytes by
//! padding in the local header's extra field, zip64 records for large archives. The crate
//! parses the directories; this module keeps the file's name on every error, refuses any
//! compression method but stored and deflated before reading a byte, and reads an entry only
//! up to the size the directory gives it (and the file really holds), checking its CRC-32.

use std::io::{Cursor, Read};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use zip::result::ZipError;
use zip::{CompressionMethod, ZipArchive};

use crate::error::{Error, Result};

/// The archive's bytes, shared so that a reader can be cloned for each `&self` read.
#[derive(Clone, Debug)]
struct Bytes(Arc<Vec<u8>>);

impl AsRef<[u8]> for Bytes {
    fn as_ref(&self) -> &[u8] {
        &self.0
    }
}

/// A zip archive in memory.
#[derive(Debug)]
pub(crate) struct Zip {
    path: PathBuf,
    len: u64,
    archive: ZipArchive<Cursor<Bytes>>,
}

impl Zip {
    /// Reads the archive `path` and its central directory.
    pub(crate) fn open(path: &Path) -> Result<Self> {
        let bytes = crate::input::read_bytes(path)?;
        Self::from_bytes(path, bytes)
    }

    /// An archive from its bytes (`path` names it in messages).
    pub(crate) fn from_bytes(path: &Path, bytes: Vec<u8>) -> Result<Self> {
        let len = bytes.len() as u64;
        let archive = ZipArchive::new(Cursor::new(Bytes(Arc::new(bytes))))
            .map_err(|e| corrupt(path, "", e))?;
        Ok(Zip {
            path: path.to_path_buf(),
            len,
            archive,
        })
    }

    /// The entries' names, in directory order.
    pub(crate) fn names(&self) -> impl Iterator<Item = &str> {
        self.archive.file_names()
    }

    /// The archive's file (for messages).
    pub(crate) fn path(&self) -> &Path {
        &self.path
    }

    /// The contents of entry `name`, CRC-checked; `None` when there is no such entry.
    pub(crate) fn read(&self, name: &str) -> Result<Option<Vec<u8>>> {
        self.read_at_most(name, u64::MAX)
    }

    /// The contents of entry `name`, CRC-checked, refused before a byte is inflated when its
    /// directory declares more than `most` bytes (what its reader can use) or more than its
    /// compressed bytes can inflate to; `None` when there is no such entry.
    pub(crate) fn read_at_most(&self, name: &str, most: u64) -> Result<Option<Vec<u8>>> {
        let Some(index) = self.archive.index_for_name(name) else {
            return Ok(None);
        };
        let what = format!("entry '{name}'");
        // A clone shares the bytes and the parsed directory; it only has its own position.
        let mut archive = self.archive.clone();
        let (method, size, end, packed) = {
            let raw = archive
                .by_index_raw(index)
                .map_err(|e| corrupt(&self.path, &what, e))?;
            let end = raw
                .data_start()
                .and_then(|start| start.checked_add(raw.compressed_size()));
            (raw.compression(), raw.size(), end, raw.compressed_size())
        };
        if !matches!(
            method,
            CompressionMethod::Stored | CompressionMethod::Deflated
        ) {
            return Err(Error::Unsupported(format!(
                "{}: {what}: {} compression (only stored and deflated zip entries)",
                self.path.display(),
                method_name(method)
            )));
        }
        if end.is_none_or(|end| end > self.len) {
            return Err(Error::format(
                &self.path,
                &what,
                "zip archive truncated: the entry runs past the end of the file",
            ));
        }
        if size > most {
            return Err(Error::format(
                &self.path,
                &what,
                format!("the directory declares {size} bytes, more than the {most} it can hold"),
            ));
        }
        if method == CompressionMethod::Deflated
            && size > packed.saturating_mul(MAX_DEFLATE_RATIO).saturating_add(64)
        {
            return Err(Error::format(
                &self.path,
                &what,
                format!(
                    "the directory declares {size} bytes, more than its {packed} deflated \
                     bytes can inflate to (deflate expands at most {MAX_DEFLATE_RATIO}-fold)"
                ),
            ));
        }
        let entry = archive
            .by_index(index)
            .map_err(|e| corrupt(&self.path, &what, e))?;
        // Never more than the directory's size (plus one byte, to see a longer stream);
        // memory grows with what the data really decodes to, not with the size claimed.
        let mut data = Vec::with_capacity(size.min(self.len) as usize);
        entry
            .take(size.saturating_add(1))
            .read_to_end(&mut data)
            .map_err(|e| corrupt(&self.path, &what, ZipError::Io(e)))?;
        if data.len() as u64 != size {
            return Err(Error::format(
                &self.path,
                &what,
                format!("holds {} bytes, the directory says {size}", data.len()),
            ));
        }
        Ok(Some(data))
    }
}

/// The most deflate expands its input: a 258-byte match in as little as 2 bits, 1032-fold.
const MAX_DEFLATE_RATIO: u64 = 1032;

/// A compression method's name and number (APPNOTE 4.4.5), for messages.
fn method_name(method: CompressionMethod) -> String {
    let known = [
        (CompressionMethod::IMPLODE, "implode (method 6)"),
        (CompressionMethod::DEFLATE64, "Deflate64 (method 9)"),
        (CompressionMethod::BZIP2, "bzip2 (method 12)"),
        (CompressionMethod::LZMA, "LZMA (method 14)"),
        (CompressionMethod::ZSTD, "Zstandard (method 93)"),
        (CompressionMethod::XZ, "xz (method 95)"),
        (CompressionMethod::PPMD, "PPMd (method 98)"),
        (CompressionMethod::AES, "AES-encrypted (method 99)"),
    ];
    known
        .iter()
        .find(|(m, _)| *m == method)
        .map_or_else(|| format!("{method:?}"), |(_, name)| name.to_string())
}

/// A zip error as an error naming the archive (and the entry, when `what` names one), in
/// the format's words: the zip library's own texts name its internals (`EOCD`, its types).
fn corrupt(path: &Path, what: &str, e: ZipError) -> Error {
    let message = match e {
        ZipError::Io(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => {
            "zip archive truncated: data runs past the end of the file".to_owned()
        }
        ZipError::Io(e) if e.to_string().contains("checksum") => {
            "CRC-32 mismatch: the data is corrupt".to_owned()
        }
        ZipError::Io(e) if e.kind() == std::io::ErrorKind::InvalidData => {
            "zip archive corrupt: the entry's compressed data does not decode".to_owned()
        }
        ZipError::Io(e) => format!("zip archive unreadable: {e}"),
        ZipError::UnsupportedArchive(_) => {
            "unsupported zip archive: split over several files, encrypted, or using a zip \
             feature nerfx does not read"
                .to_owned()
        }
        ZipError::InvalidPassword => "unsupported zip archive: it is encrypted".to_owned(),
        _ if what.is_empty() => "not a readable zip archive (its directory at the end of the \
                                 file is missing or damaged: truncated or corrupt): a torch \
                                 checkpoint is a zip archive"
            .to_owned(),
        _ => "zip archive corrupt: the entry's header disagrees with the archive's directory"
            .to_owned(),
    };
    Error::format(path, what, message)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stored-entry archive written from the APPNOTE layout, independently of the reader.
    fn archive(files: &[(&str, &[u8])]) -> Vec<u8> {
        let entries: Vec<_> = files.iter().map(|&(n, d)| (n, 0, d.to_vec(), d)).collect();
        archive_with(&entries)
    }

    /// An archive of `(name, method, bytes as written, contents)` entries (APPNOTE layout:
    /// local headers with a 3-byte extra field, central directory, end record).
    fn archive_with(files: &[(&str, u16, Vec<u8>, &[u8])]) -> Vec<u8> {
        let mut out = Vec::new();
        let mut central = Vec::new();
        for (name, method, raw, data) in files {
            let mut crc = flate2::Crc::new();
            crc.update(data);
            let offset = out.len() as u32;
            out.extend(0x0403_4b50u32.to_le_bytes());
            out.extend([20, 0, 0, 0]);
            out.extend(method.to_le_bytes());
            out.extend([0, 0, 0, 0]);
            out.extend(crc.sum().to_le_bytes());
            out.extend((raw.len() as u32).to_le_bytes());
            out.extend((data.len() as u32).to_le_bytes());
            out.extend((name.len() as u16).to_le_bytes());
            out.extend(3u16.to_le_bytes());
            out.extend(name.as_bytes());
            out.extend([0, 0, 0]);
            out.extend(raw);
            central.extend(0x0201_4b50u32.to_le_bytes());
            central.extend([20, 0, 20, 0, 0, 0]);
            central.extend(method.to_le_bytes());
            central.extend([0, 0, 0, 0]);
            central.extend(crc.sum().to_le_bytes());
            central.extend((raw.len() as u32).to_le_bytes());
            central.extend((data.len() as u32).to_le_bytes());
            central.extend((name.len() as u16).to_le_bytes());
            central.extend([0u8; 12]);
            central.extend(offset.to_le_bytes());
            central.extend(name.as_bytes());
        }
        let cd_offset = out.len() as u32;
        out.extend(&central);
        out.extend(0x0605_4b50u32.to_le_bytes());
        out.extend([0, 0, 0, 0]);
        out.extend((files.len() as u16).to_le_bytes());
        out.extend((files.len() as u16).to_le_bytes());
        out.extend((central.len() as u32).to_le_bytes());
        out.extend(cd_offset.to_le_bytes());
        out.extend([0, 0]);
        out
    }

    #[test]
    fn reads_stored_entries() {
        let bytes = archive(&[("a/data.pkl", b"hello"), ("a/data/0", &[1, 2, 3, 4])]);
        let z = Zip::from_bytes(Path::new("x.ckpt"), bytes).unwrap();
        assert_eq!(z.names().collect::<Vec<_>>(), ["a/data.pkl", "a/data/0"]);
        assert_eq!(&*z.read("a/data.pkl").unwrap().unwrap(), b"hello");
        assert_eq!(&*z.read("a/data/0").unwrap().unwrap(), &[1, 2, 3, 4]);
        assert!(z.read("missing").unwrap().is_none());
    }

    #[test]
    fn corruption_and_truncation_are_errors_naming_the_file() {
        let bytes = archive(&[("a/data.pkl", b"hello world"), ("a/data/0", &[7; 64])]);
        // A flipped data byte: CRC mismatch.
        let mut flipped = bytes.clone();
        let at = flipped.windows(5).position(|w| w == b"hello").unwrap();
        flipped[at] ^= 0x20;
        let z = Zip::from_bytes(Path::new("x.ckpt"), flipped).unwrap();
        let e = z.read("a/data.pkl").unwrap_err().to_string();
        assert!(e.contains("x.ckpt") && e.contains("CRC"), "{e}");
        // Every truncation is an error (or, cut inside the trailing record, still an error).
        for cut in 0..bytes.len() {
            let r = Zip::from_bytes(Path::new("x.ckpt"), bytes[..cut].to_vec())
                .and_then(|z| z.read("a/data/0").map(|_| ()));
            let e = r.expect_err("truncated archive accepted").to_string();
            assert!(e.contains("x.ckpt"), "{e}");
        }
    }

    #[test]
    fn reads_deflated_entries() {
        let data: Vec<u8> = (0..5000u32).map(|i| (i % 251) as u8).collect();
        let mut enc = flate2::write::DeflateEncoder::new(Vec::new(), flate2::Compression::best());
        std::io::Write::write_all(&mut enc, &data).unwrap();
        let raw = enc.finish().unwrap();
        assert!(raw.len() < data.len());
        let bytes = archive_with(&[("a/data/0", 8, raw, &data)]);
        let z = Zip::from_bytes(Path::new("x.ckpt"), bytes).unwrap();
        assert_eq!(z.read("a/data/0").unwrap().unwrap(), data);
    }

    #[test]
    fn entries_declaring_more_than_they_can_hold_are_refused_before_inflating() {
        let data = vec![0u8; 5000];
        let mut enc = flate2::write::DeflateEncoder::new(Vec::new(), flate2::Compression::best());
        std::io::Write::write_all(&mut enc, &data).unwrap();
        let raw = enc.finish().unwrap();
        // More than the reader can use.
        let bytes = archive_with(&[("a/data/0", 8, raw.clone(), &data)]);
        let z = Zip::from_bytes(Path::new("x.ckpt"), bytes).unwrap();
        let e = z.read_at_most("a/data/0", 4999).unwrap_err().to_string();
        assert!(
            e.contains("a/data/0") && e.contains("declares 5000 bytes"),
            "{e}"
        );
        assert_eq!(z.read_at_most("a/data/0", 5000).unwrap().unwrap(), data);
        // More than deflate expands its bytes to: the sizes claim a 4 GiB - 1 entry.
        let mut bytes = archive_with(&[("a/data/0", 8, raw.clone(), &data)]);
        for sig in [0x0403_4b50u32, 0x0201_4b50] {
            let at = bytes
                .windows(4)
                .position(|w| w == sig.to_le_bytes())
                .unwrap();
            let size = if sig == 0x0403_4b50 { at + 22 } else { at + 24 };
            bytes[size..size + 4].copy_from_slice(&u32::MAX.to_le_bytes());
        }
        let z = Zip::from_bytes(Path::new("x.ckpt"), bytes).unwrap();
        let e = z.read("a/data/0").unwrap_err().to_string();
        assert!(
            e.contains("more than its") && e.contains("1032-fold"),
            "{e}"
        );
    }

    #[test]
    fn other_compression_methods_are_refused_naming_file_and_entry() {
        // bzip2 (12) and LZMA (14): the bytes must never be handed out as if stored.
        for method in [12u16, 14] {
            let bytes = archive_with(&[("a/data.pkl", method, b"hello".to_vec(), b"hello")]);
            let z = Zip::from_bytes(Path::new("x.ckpt"), bytes).unwrap();
            let e = z.read("a/data.pkl").unwrap_err().to_string();
            assert!(
                e.contains("x.ckpt")
                    && e.contains("a/data.pkl")
                    && e.contains(&format!("method {method})")),
                "{e}"
            );
        }
    }

    #[test]
    fn an_entry_larger_than_the_file_is_refused() {
        // The directory and local header claim 1 GiB: refused before anything is allocated.
        let mut bytes = archive(&[("a/data/0", &[5; 16])]);
        for sig in [0x0403_4b50u32, 0x0201_4b50] {
            let at = bytes
                .windows(4)
                .position(|w| w == sig.to_le_bytes())
                .unwrap();
            let sizes = if sig == 0x0403_4b50 { at + 18 } else { at + 20 };
            bytes[sizes..sizes + 8].copy_from_slice(&[0, 0, 0, 64, 0, 0, 0, 64]);
        }
        let r = Zip::from_bytes(Path::new("x.ckpt"), bytes).and_then(|z| z.read("a/data/0"));
        let e = r.unwrap_err().to_string();
        assert!(e.contains("x.ckpt"), "{e}");
    }
}
