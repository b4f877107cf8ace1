//! instant-ngp's snapshot container: msgpack, optionally gzip-framed, read into a value tree
//! and walked with messages that name the file and the key path.

use std::io::{Cursor, Read};
use std::path::Path;

use glam::Vec3;
use rmpv::Value;

use crate::error::{Error, Result};

/// Msgpack access that names the key path in errors.
pub(crate) struct Doc<'a> {
    /// The file, for messages.
    pub(crate) path: &'a Path,
}

impl Doc<'_> {
    pub(crate) fn err(&self, at: &str, msg: impl Into<String>) -> Error {
        Error::format(self.path, at, msg)
    }

    pub(crate) fn get<'v>(&self, v: &'v Value, at: &str, key: &str) -> Result<&'v Value> {
        self.find(v, key)
            .ok_or_else(|| self.err(at, format!("missing key '{key}'")))
    }

    pub(crate) fn find<'v>(&self, v: &'v Value, key: &str) -> Option<&'v Value> {
        v.as_map()?
            .iter()
            .find(|(k, _)| k.as_str() == Some(key))
            .map(|(_, v)| v)
    }

    pub(crate) fn f64(&self, v: &Value, at: &str) -> Result<f64> {
        v.as_f64()
            .or_else(|| v.as_i64().map(|i| i as f64))
            .or_else(|| v.as_u64().map(|i| i as f64))
            .filter(|x| x.is_finite())
            .ok_or_else(|| self.err(at, format!("expected a finite number, found {v}")))
    }

    pub(crate) fn u32_or(&self, v: &Value, at: &str, key: &str, default: u32) -> Result<u32> {
        match self.find(v, key) {
            None => Ok(default),
            Some(x) => x
                .as_u64()
                .and_then(|x| u32::try_from(x).ok())
                .ok_or_else(|| {
                    self.err(
                        &format!("{at}.{key}"),
                        format!("expected a count, found {x}"),
                    )
                }),
        }
    }

    pub(crate) fn vec3(&self, v: &Value, at: &str) -> Result<Vec3> {
        let a = v
            .as_array()
            .filter(|a| a.len() == 3)
            .ok_or_else(|| self.err(at, "expected an array of 3 numbers"))?;
        let mut out = [0.0f32; 3];
        for (o, x) in out.iter_mut().zip(a) {
            *o = self.f64(x, at)? as f32;
        }
        Ok(Vec3::from_array(out))
    }

    pub(crate) fn bytes<'v>(&self, v: &'v Value, at: &str) -> Result<&'v [u8]> {
        v.as_slice()
            .ok_or_else(|| self.err(at, "expected binary data"))
    }
}

/// Reads the file and decodes its msgpack (inflating it first when it is gzip-framed).
pub(crate) fn read_document(path: &Path) -> Result<(Value, bool)> {
    let raw = crate::input::read_bytes(path)?;
    let gzip = raw.starts_with(&[0x1f, 0x8b]);
    let bytes = if gzip {
        let mut out = Vec::new();
        flate2::read::GzDecoder::new(raw.as_slice())
            .read_to_end(&mut out)
            .map_err(|e| Error::format(path, "gzip stream", e.to_string()))?;
        out
    } else {
        raw
    };
    let mut cursor = Cursor::new(bytes.as_slice());
    let value = rmpv::decode::read_value(&mut cursor).map_err(|e| {
        Error::format(
            path,
            format!("byte {}", cursor.position()),
            format!("not a valid msgpack snapshot: {e}"),
        )
    })?;
    Ok((value, gzip))
}
