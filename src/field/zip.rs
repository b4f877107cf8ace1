//! A minimal reader of zip archives held in memory: the container of torch checkpoints.
//!
//! Torch writes its archives with miniz: every entry stored (method 0), data aligned to 64
//! bytes by padding in the local header's extra field, zip64 records for large archives.
//! This reader finds the end-of-central-directory record (and its zip64 form), walks the
//! central directory, and hands out an entry's bytes after checking their CRC-32; stored and
//! deflated (method 8, inflated with flate2) entries are read, others refused.
//!
//! Layout facts used (PKWARE APPNOTE): end record `PK\5\6` (entries u16 at +10, directory
//! size u32 at +12, offset u32 at +16); zip64 locator `PK\6\7` 20 bytes before it (record
//! offset u64 at +8); zip64 end record `PK\6\6` (entries u64 at +32, size at +40, offset at
//! +48); central header `PK\1\2` (method +10, CRC +16, sizes +20/+24, name/extra/comment
//! lengths +28/+30/+32, local offset +42, name +46; zip64 extra field id 1 holds the
//! saturated values in the order uncompressed, compressed, offset); local header `PK\3\4`
//! (name and extra lengths +26/+28, data at +30 + both).

use std::borrow::Cow;
use std::io::Read;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// One entry of the central directory.
#[derive(Clone, Debug)]
struct Entry {
    name: String,
    method: u16,
    crc: u32,
    compressed: u64,
    uncompressed: u64,
    local_offset: u64,
}

/// A zip archive in memory.
#[derive(Debug)]
pub(crate) struct Zip {
    path: PathBuf,
    bytes: Vec<u8>,
    entries: Vec<Entry>,
}

/// Little-endian reads that fail with the file and offset instead of panicking.
struct At<'a> {
    path: &'a Path,
    bytes: &'a [u8],
}

impl<'a> At<'a> {
    fn slice(&self, at: u64, len: u64, what: &str) -> Result<&'a [u8]> {
        let end = at
            .checked_add(len)
            .filter(|&e| e <= self.bytes.len() as u64);
        match end {
            Some(end) => Ok(&self.bytes[at as usize..end as usize]),
            None => Err(Error::format(
                self.path,
                format!("byte {at}"),
                format!("zip archive truncated: {what} runs past the end of the file"),
            )),
        }
    }

    fn u16(&self, at: u64, what: &str) -> Result<u16> {
        let b = self.slice(at, 2, what)?;
        Ok(u16::from_le_bytes([b[0], b[1]]))
    }

    fn u32(&self, at: u64, what: &str) -> Result<u32> {
        let b = self.slice(at, 4, what)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    fn u64(&self, at: u64, what: &str) -> Result<u64> {
        let b = self.slice(at, 8, what)?;
        let mut a = [0u8; 8];
        a.copy_from_slice(b);
        Ok(u64::from_le_bytes(a))
    }

    fn expect_signature(&self, at: u64, sig: u32, what: &str) -> Result<()> {
        if self.u32(at, what)? == sig {
            Ok(())
        } else {
            Err(Error::format(
                self.path,
                format!("byte {at}"),
                format!("zip archive corrupt: no {what} signature"),
            ))
        }
    }
}

const END: u32 = 0x0605_4b50;
const END64_LOCATOR: u32 = 0x0706_4b50;
const END64: u32 = 0x0606_4b50;
const CENTRAL: u32 = 0x0201_4b50;
const LOCAL: u32 = 0x0403_4b50;

impl Zip {
    /// Reads the archive `path` and its central directory.
    pub(crate) fn open(path: &Path) -> Result<Self> {
        let bytes = crate::input::read_bytes(path)?;
        Self::from_bytes(path, bytes)
    }

    /// An archive from its bytes (`path` names it in messages).
    pub(crate) fn from_bytes(path: &Path, bytes: Vec<u8>) -> Result<Self> {
        let entries = read_directory(&At {
            path,
            bytes: &bytes,
        })?;
        Ok(Zip {
            path: path.to_path_buf(),
            bytes,
            entries,
        })
    }

    /// The entries' names, in directory order.
    pub(crate) fn names(&self) -> impl Iterator<Item = &str> {
        self.entries.iter().map(|e| e.name.as_str())
    }

    /// The archive's file (for messages).
    pub(crate) fn path(&self) -> &Path {
        &self.path
    }

    /// The contents of entry `name`, CRC-checked; `None` when there is no such entry.
    pub(crate) fn read(&self, name: &str) -> Result<Option<Cow<'_, [u8]>>> {
        let Some(e) = self.entries.iter().find(|e| e.name == name) else {
            return Ok(None);
        };
        let at = At {
            path: &self.path,
            bytes: &self.bytes,
        };
        let what = format!("entry '{name}'");
        at.expect_signature(e.local_offset, LOCAL, &format!("local header of {what}"))?;
        let n = u64::from(at.u16(e.local_offset + 26, &what)?);
        let x = u64::from(at.u16(e.local_offset + 28, &what)?);
        let raw = at.slice(e.local_offset + 30 + n + x, e.compressed, &what)?;
        let data: Cow<[u8]> = match e.method {
            0 => Cow::Borrowed(raw),
            8 => {
                let mut out = Vec::with_capacity(e.uncompressed.min(1 << 30) as usize);
                flate2::read::DeflateDecoder::new(raw)
                    .read_to_end(&mut out)
                    .map_err(|err| {
                        Error::format(&self.path, &what, format!("bad deflate data: {err}"))
                    })?;
                Cow::Owned(out)
            }
            m => {
                return Err(Error::Unsupported(format!(
                    "{}: {what}: zip compression method {m} (only stored and deflated entries)",
                    self.path.display()
                )))
            }
        };
        if data.len() as u64 != e.uncompressed {
            return Err(Error::format(
                &self.path,
                &what,
                format!(
                    "holds {} bytes, the directory says {}",
                    data.len(),
                    e.uncompressed
                ),
            ));
        }
        let mut crc = flate2::Crc::new();
        crc.update(&data);
        if crc.sum() != e.crc {
            return Err(Error::format(
                &self.path,
                &what,
                "CRC-32 mismatch: the data is corrupt",
            ));
        }
        Ok(Some(data))
    }
}

/// Finds the end record and reads every central-directory entry.
fn read_directory(at: &At) -> Result<Vec<Entry>> {
    let len = at.bytes.len();
    let first = len.saturating_sub(22 + 65_535);
    let end = (first..(len + 1).saturating_sub(22))
        .rev()
        .find(|&i| at.bytes[i..i + 4] == END.to_le_bytes())
        .ok_or_else(|| {
            Error::format(
                at.path,
                "",
                "not a zip archive (no end-of-central-directory record): truncated or not a \
                 torch checkpoint",
            )
        })? as u64;
    let mut count = u64::from(at.u16(end + 10, "end record")?);
    let mut size = u64::from(at.u32(end + 12, "end record")?);
    let mut offset = u64::from(at.u32(end + 16, "end record")?);
    if (count == 0xFFFF || size == 0xFFFF_FFFF || offset == 0xFFFF_FFFF) && end >= 20 {
        let loc = end - 20;
        at.expect_signature(loc, END64_LOCATOR, "zip64 end locator")?;
        let rec = at.u64(loc + 8, "zip64 end locator")?;
        at.expect_signature(rec, END64, "zip64 end record")?;
        count = at.u64(rec + 32, "zip64 end record")?;
        size = at.u64(rec + 40, "zip64 end record")?;
        offset = at.u64(rec + 48, "zip64 end record")?;
    }
    at.slice(offset, size, "central directory")?;
    let mut entries = Vec::new();
    let mut p = offset;
    for i in 0..count {
        let what = format!("central directory entry {i}");
        at.expect_signature(p, CENTRAL, &what)?;
        let n = u64::from(at.u16(p + 28, &what)?);
        let x = u64::from(at.u16(p + 30, &what)?);
        let c = u64::from(at.u16(p + 32, &what)?);
        let name = String::from_utf8(at.slice(p + 46, n, &what)?.to_vec()).map_err(|_| {
            Error::format(at.path, &what, "entry name is not UTF-8: corrupt archive")
        })?;
        let mut e = Entry {
            name,
            method: at.u16(p + 10, &what)?,
            crc: at.u32(p + 16, &what)?,
            compressed: u64::from(at.u32(p + 20, &what)?),
            uncompressed: u64::from(at.u32(p + 24, &what)?),
            local_offset: u64::from(at.u32(p + 42, &what)?),
        };
        read_zip64_extra(at, p + 46 + n, x, &mut e, &what)?;
        entries.push(e);
        p += 46 + n + x + c;
    }
    Ok(entries)
}

/// Replaces the saturated sizes and offset of `e` by the zip64 extra field's values.
fn read_zip64_extra(at: &At, start: u64, len: u64, e: &mut Entry, what: &str) -> Result<()> {
    let mut q = start;
    while q + 4 <= start + len {
        let id = at.u16(q, what)?;
        let size = u64::from(at.u16(q + 2, what)?);
        if id == 1 {
            let mut r = q + 4;
            for v in [&mut e.uncompressed, &mut e.compressed, &mut e.local_offset] {
                if *v == 0xFFFF_FFFF && r + 8 <= q + 4 + size {
                    *v = at.u64(r, what)?;
                    r += 8;
                }
            }
        }
        q += 4 + size;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stored-entry archive written from the APPNOTE layout, independently of the reader.
    fn archive(files: &[(&str, &[u8])]) -> Vec<u8> {
        let mut out = Vec::new();
        let mut central = Vec::new();
        for (name, data) in files {
            let mut crc = flate2::Crc::new();
            crc.update(data);
            let offset = out.len() as u32;
            out.extend(0x0403_4b50u32.to_le_bytes());
            out.extend([20, 0, 0, 0, 0, 0, 0, 0, 0, 0]);
            out.extend(crc.sum().to_le_bytes());
            out.extend((data.len() as u32).to_le_bytes());
            out.extend((data.len() as u32).to_le_bytes());
            out.extend((name.len() as u16).to_le_bytes());
            out.extend(3u16.to_le_bytes());
            out.extend(name.as_bytes());
            out.extend([0, 0, 0]);
            out.extend(*data);
            central.extend(0x0201_4b50u32.to_le_bytes());
            central.extend([20, 0, 20, 0, 0, 0, 0, 0, 0, 0, 0, 0]);
            central.extend(crc.sum().to_le_bytes());
            central.extend((data.len() as u32).to_le_bytes());
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
}
