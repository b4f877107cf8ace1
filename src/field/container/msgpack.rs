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

/// The most a gzip-framed snapshot may inflate to: 4 GiB, above the largest hash grid
/// instant-ngp trains (2²⁴ entries per level) in half precision.
const MAX_INFLATED_BYTES: u64 = 4 << 30;

/// Reads the file and decodes its msgpack, inflating a gzip-framed one as it is decoded: a
/// stream that is not a snapshot fails at its first bad byte without being inflated whole,
/// and no stream is inflated beyond [`MAX_INFLATED_BYTES`]. (The decoder allocates binary
/// data as it arrives, never by the length a header claims.)
pub(crate) fn read_document(path: &Path) -> Result<(Value, bool)> {
    let raw = crate::input::read_bytes(path)?;
    let gzip = raw.starts_with(&[0x1f, 0x8b]);
    let decoded = if gzip {
        let inflated = flate2::read::GzDecoder::new(raw.as_slice()).take(MAX_INFLATED_BYTES);
        let mut stream = CountingReader {
            inner: std::io::BufReader::new(inflated),
            count: 0,
        };
        let decoded = rmpv::decode::read_value(&mut stream);
        let at = stream.count;
        let decoded = decoded.map_err(|e| {
            let why = match &e {
                rmpv::decode::Error::InvalidMarkerRead(io)
                | rmpv::decode::Error::InvalidDataRead(io)
                    if io.kind() != std::io::ErrorKind::UnexpectedEof =>
                {
                    format!("not a valid gzip stream: {io}")
                }
                _ if at >= MAX_INFLATED_BYTES => format!(
                    "inflates to more than {} GiB, more than any snapshot holds",
                    MAX_INFLATED_BYTES >> 30
                ),
                _ => format!("not a valid msgpack snapshot: {e}"),
            };
            Error::format(path, format!("inflated byte {at}"), why)
        })?;
        if decoded.is_map() && stream.read(&mut [0u8]).map_or(true, |n| n > 0) {
            return Err(Error::format(
                path,
                format!("inflated byte {at}"),
                "not an instant-ngp snapshot: its msgpack ends here, before the end of the \
                 stream",
            ));
        }
        decoded
    } else {
        let mut cursor = Cursor::new(raw.as_slice());
        let value = rmpv::decode::read_value(&mut cursor).map_err(|e| {
            Error::format(
                path,
                format!("byte {}", cursor.position()),
                format!("not a valid msgpack snapshot: {e}"),
            )
        })?;
        if cursor.position() != raw.len() as u64 {
            return Err(Error::format(
                path,
                format!("byte {}", cursor.position()),
                format!(
                    "not an instant-ngp snapshot: its msgpack ends here, {} bytes before the \
                     end of the file",
                    raw.len() as u64 - cursor.position()
                ),
            ));
        }
        value
    };
    if !decoded.is_map() {
        let kind = match &decoded {
            Value::Nil => "nil",
            Value::Boolean(_) => "a boolean",
            Value::Integer(_) => "an integer",
            Value::F32(_) | Value::F64(_) => "a number",
            Value::String(_) => "a string",
            Value::Binary(_) => "binary data",
            Value::Array(_) => "an array",
            Value::Map(_) => "a map",
            Value::Ext(..) => "an extension value",
        };
        return Err(Error::format(
            path,
            "top level",
            format!("not an instant-ngp snapshot: it holds {kind}, not a map of keys"),
        ));
    }
    Ok((decoded, gzip))
}

/// Counts the bytes read through it (for messages: where in the stream decoding stopped).
struct CountingReader<R> {
    inner: R,
    count: u64,
}

impl<R: Read> Read for CountingReader<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.count += n as u64;
        Ok(n)
    }
}
