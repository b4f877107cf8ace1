//! instant-ngp's snapshot container: msgpack, optionally gzip-framed, read into a value tree
//! and walked with messages that name the file and the key path.
//!
//! **Bounded decoding.** A msgpack header declares the length of the binary, string or
//! extension that follows, and a gzip stream can inflate a thousandfold: a small file can
//! claim gigabytes. So the decoder asks its caller about every such payload, by key path and
//! declared length, before reading a byte of it: keep it, skip it (read past it, keeping its
//! length only) or refuse the file. The caller bounds each payload by what its field can
//! hold, from what the document has said so far (see [`Payload::top`]). Arrays and maps are
//! never allocated by the count they claim, nesting is limited to [`MAX_DEPTH`] levels and
//! the whole document to [`MAX_VALUES`] values, so memory follows what the stream really
//! holds.

use std::io::Read;
use std::path::Path;

use glam::Vec3;
use rmpv::{Integer, Value};

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

/// The deepest nesting of arrays and maps accepted (a snapshot nests six levels).
pub(crate) const MAX_DEPTH: usize = 32;

/// The most values a document may hold (a snapshot of a thousand-image capture holds about a
/// hundred thousand); each takes some 40 bytes in memory, from as little as 1 in the file.
pub(crate) const MAX_VALUES: u64 = 1 << 20;

/// A binary, string or extension value about to be read.
pub(crate) struct Payload<'a> {
    /// Its key path, dotted (`snapshot.params_binary`; array items as `xforms[3]`).
    pub(crate) at: &'a str,
    /// What it is.
    pub(crate) kind: PayloadKind,
    /// The length its header declares, in bytes.
    pub(crate) len: u64,
    /// The top-level entries decoded before it (the entry holding it excluded).
    pub(crate) top: &'a [(Value, Value)],
}

/// The kinds of values whose header declares a length.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum PayloadKind {
    Binary,
    String,
    Extension,
}

/// What the caller says of a [`Payload`].
pub(crate) enum Verdict {
    /// Read it into the document.
    Keep,
    /// Read past it: the document holds nil in its place, and its path and length are
    /// reported in [`Decoded::skipped`].
    Skip,
    /// Refuse the document with this message (the payload's path is prefixed).
    Refuse(String),
}

/// A decoded document.
pub(crate) struct Decoded {
    /// The value tree (the top level is a map).
    pub(crate) top: Value,
    /// Whether the file was gzip-framed.
    pub(crate) gzip: bool,
    /// The payloads skipped: key path and declared length.
    pub(crate) skipped: Vec<(String, u64)>,
}

/// Reads the file and decodes its msgpack, inflating a gzip-framed one as it is decoded:
/// a stream that is not a snapshot fails at its first bad byte without being inflated
/// whole, no stream is inflated beyond [`MAX_INFLATED_BYTES`], and every payload is judged
/// by `judge` before it is read.
pub(crate) fn read_document(
    path: &Path,
    judge: &mut dyn FnMut(&Payload) -> Verdict,
) -> Result<Decoded> {
    let raw = crate::input::read_bytes(path)?;
    let gzip = raw.starts_with(&[0x1f, 0x8b]);
    let where_ = |at: u64| {
        if gzip {
            format!("inflated byte {at}")
        } else {
            format!("byte {at}")
        }
    };
    let mut decoder = if gzip {
        let inflated = flate2::read::GzDecoder::new(raw.as_slice()).take(MAX_INFLATED_BYTES);
        Decoder::new(
            Box::new(std::io::BufReader::new(inflated)) as Box<dyn Read + '_>,
            judge,
        )
    } else {
        Decoder::new(Box::new(raw.as_slice()) as Box<dyn Read + '_>, judge)
    };
    let top = match decoder.document() {
        Ok(top) => top,
        Err(fail) => {
            let at = decoder.pos;
            let why = match fail {
                Fail::Io(io) if gzip && io.kind() != std::io::ErrorKind::UnexpectedEof => {
                    format!("not a valid gzip stream: {io}")
                }
                Fail::Io(_) if gzip && at >= MAX_INFLATED_BYTES => format!(
                    "inflates to more than {} GiB, more than any snapshot holds",
                    MAX_INFLATED_BYTES >> 30
                ),
                Fail::Io(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
                    "not a valid msgpack snapshot: the data ends inside a value (truncated)"
                        .to_owned()
                }
                Fail::Io(io) => format!("not a valid msgpack snapshot: {io}"),
                Fail::Malformed(why) => format!("not a valid msgpack snapshot: {why}"),
                Fail::Refused(at, why) => return Err(Error::format(path, at, why)),
                Fail::NotAMap(kind) => {
                    return Err(Error::format(
                        path,
                        "top level",
                        format!("not an instant-ngp snapshot: it holds {kind}, not a map of keys"),
                    ))
                }
            };
            return Err(Error::format(path, where_(at), why));
        }
    };
    let at = decoder.pos;
    let more = decoder.rd.read(&mut [0u8]).map_or(true, |n| n > 0);
    if more {
        let why = if gzip {
            "not an instant-ngp snapshot: its msgpack ends here, before the end of the stream"
                .to_owned()
        } else {
            format!(
                "not an instant-ngp snapshot: its msgpack ends here, {} bytes before the end \
                 of the file",
                raw.len() as u64 - at
            )
        };
        return Err(Error::format(path, where_(at), why));
    }
    let skipped = std::mem::take(&mut decoder.skipped);
    Ok(Decoded { top, gzip, skipped })
}

/// Why decoding stopped.
enum Fail {
    Io(std::io::Error),
    Malformed(String),
    /// The judge refused the payload at this key path.
    Refused(String, String),
    /// The document is not a map: what it is.
    NotAMap(&'static str),
}

impl From<std::io::Error> for Fail {
    fn from(e: std::io::Error) -> Self {
        Fail::Io(e)
    }
}

/// A msgpack decoder (the format as its specification gives it) that judges payloads.
struct Decoder<'j, R> {
    rd: R,
    /// Bytes consumed.
    pos: u64,
    values: u64,
    judge: &'j mut dyn FnMut(&Payload) -> Verdict,
    top: Vec<(Value, Value)>,
    skipped: Vec<(String, u64)>,
}

impl<'j, R: Read> Decoder<'j, R> {
    fn new(rd: R, judge: &'j mut dyn FnMut(&Payload) -> Verdict) -> Self {
        Decoder {
            rd,
            pos: 0,
            values: 0,
            judge,
            top: Vec::new(),
            skipped: Vec::new(),
        }
    }

    fn bytes<const N: usize>(&mut self) -> std::result::Result<[u8; N], Fail> {
        let mut b = [0u8; N];
        self.rd.read_exact(&mut b)?;
        self.pos += N as u64;
        Ok(b)
    }

    fn u8(&mut self) -> std::result::Result<u8, Fail> {
        Ok(self.bytes::<1>()?[0])
    }

    fn u16(&mut self) -> std::result::Result<u64, Fail> {
        Ok(u64::from(u16::from_be_bytes(self.bytes()?)))
    }

    fn u32(&mut self) -> std::result::Result<u64, Fail> {
        Ok(u64::from(u32::from_be_bytes(self.bytes()?)))
    }

    /// The whole document: a map, whose entries the judge sees as they complete.
    fn document(&mut self) -> std::result::Result<Value, Fail> {
        let marker = self.u8()?;
        let n = match marker {
            0x80..=0x8f => u64::from(marker & 0x0f),
            0xde => self.u16()?,
            0xdf => self.u32()?,
            _ => {
                let value = self.value_after(marker, "", 0)?;
                return Err(Fail::NotAMap(kind_of(&value)));
            }
        };
        self.count()?;
        for _ in 0..n {
            let key = self.value("", 1)?;
            let at = key.as_str().unwrap_or("?").to_owned();
            let value = self.value(&at, 1)?;
            self.top.push((key, value));
        }
        Ok(Value::Map(std::mem::take(&mut self.top)))
    }

    fn count(&mut self) -> std::result::Result<(), Fail> {
        self.values += 1;
        if self.values > MAX_VALUES {
            return Err(Fail::Malformed(format!(
                "more than {MAX_VALUES} values, more than any snapshot holds"
            )));
        }
        Ok(())
    }

    fn value(&mut self, at: &str, depth: usize) -> std::result::Result<Value, Fail> {
        let marker = self.u8()?;
        self.value_after(marker, at, depth)
    }

    fn value_after(
        &mut self,
        marker: u8,
        at: &str,
        depth: usize,
    ) -> std::result::Result<Value, Fail> {
        self.count()?;
        let int = |v: u64| Value::Integer(Integer::from(v));
        let sint = |v: i64| Value::Integer(Integer::from(v));
        Ok(match marker {
            0x00..=0x7f => int(u64::from(marker)),
            0xe0..=0xff => sint(i64::from(marker as i8)),
            0x80..=0x8f => self.map(u64::from(marker & 0x0f), at, depth)?,
            0x90..=0x9f => self.array(u64::from(marker & 0x0f), at, depth)?,
            0xa0..=0xbf => self.payload(PayloadKind::String, u64::from(marker & 0x1f), at)?,
            0xc0 => Value::Nil,
            0xc1 => return Err(Fail::Malformed("byte 0xc1 is never used".to_owned())),
            0xc2 => Value::Boolean(false),
            0xc3 => Value::Boolean(true),
            0xc4 => {
                let n = u64::from(self.u8()?);
                self.payload(PayloadKind::Binary, n, at)?
            }
            0xc5 => {
                let n = self.u16()?;
                self.payload(PayloadKind::Binary, n, at)?
            }
            0xc6 => {
                let n = self.u32()?;
                self.payload(PayloadKind::Binary, n, at)?
            }
            0xc7..=0xc9 => {
                let n = match marker {
                    0xc7 => u64::from(self.u8()?),
                    0xc8 => self.u16()?,
                    _ => self.u32()?,
                };
                self.payload(PayloadKind::Extension, n, at)?
            }
            0xca => Value::F32(f32::from_be_bytes(self.bytes()?)),
            0xcb => Value::F64(f64::from_be_bytes(self.bytes()?)),
            0xcc => int(u64::from(self.u8()?)),
            0xcd => int(self.u16()?),
            0xce => int(self.u32()?),
            0xcf => int(u64::from_be_bytes(self.bytes()?)),
            0xd0 => sint(i64::from(i8::from_be_bytes(self.bytes()?))),
            0xd1 => sint(i64::from(i16::from_be_bytes(self.bytes()?))),
            0xd2 => sint(i64::from(i32::from_be_bytes(self.bytes()?))),
            0xd3 => sint(i64::from_be_bytes(self.bytes()?)),
            0xd4..=0xd8 => self.payload(PayloadKind::Extension, 1 << (marker - 0xd4), at)?,
            0xd9 => {
                let n = u64::from(self.u8()?);
                self.payload(PayloadKind::String, n, at)?
            }
            0xda => {
                let n = self.u16()?;
                self.payload(PayloadKind::String, n, at)?
            }
            0xdb => {
                let n = self.u32()?;
                self.payload(PayloadKind::String, n, at)?
            }
            0xdc => {
                let n = self.u16()?;
                self.array(n, at, depth)?
            }
            0xdd => {
                let n = self.u32()?;
                self.array(n, at, depth)?
            }
            0xde => {
                let n = self.u16()?;
                self.map(n, at, depth)?
            }
            0xdf => {
                let n = self.u32()?;
                self.map(n, at, depth)?
            }
        })
    }

    fn deeper(&self, depth: usize) -> std::result::Result<usize, Fail> {
        if depth >= MAX_DEPTH {
            return Err(Fail::Malformed(format!(
                "arrays and maps nested more than {MAX_DEPTH} deep"
            )));
        }
        Ok(depth + 1)
    }

    fn array(&mut self, n: u64, at: &str, depth: usize) -> std::result::Result<Value, Fail> {
        let depth = self.deeper(depth)?;
        // Never allocated by the claimed count: each item takes at least a byte.
        let mut items = Vec::with_capacity(n.min(1024) as usize);
        for i in 0..n {
            items.push(self.value(&format!("{at}[{i}]"), depth)?);
        }
        Ok(Value::Array(items))
    }

    fn map(&mut self, n: u64, at: &str, depth: usize) -> std::result::Result<Value, Fail> {
        let depth = self.deeper(depth)?;
        let mut entries = Vec::with_capacity(n.min(1024) as usize);
        for _ in 0..n {
            let key = self.value(at, depth)?;
            let path = match key.as_str() {
                Some(k) if at.is_empty() => k.to_owned(),
                Some(k) => format!("{at}.{k}"),
                None => format!("{at}.?"),
            };
            let value = self.value(&path, depth)?;
            entries.push((key, value));
        }
        Ok(Value::Map(entries))
    }

    /// A binary, string or extension of `len` bytes, judged before it is read.
    fn payload(
        &mut self,
        kind: PayloadKind,
        len: u64,
        at: &str,
    ) -> std::result::Result<Value, Fail> {
        let ext_type = if kind == PayloadKind::Extension {
            Some(i8::from_be_bytes(self.bytes()?))
        } else {
            None
        };
        let verdict = (self.judge)(&Payload {
            at,
            kind,
            len,
            top: &self.top,
        });
        match verdict {
            Verdict::Refuse(why) => Err(Fail::Refused(at.to_owned(), why)),
            Verdict::Skip => {
                let n = std::io::copy(&mut (&mut self.rd).take(len), &mut std::io::sink())?;
                self.pos += n;
                if n < len {
                    return Err(Fail::Io(std::io::ErrorKind::UnexpectedEof.into()));
                }
                self.skipped.push((at.to_owned(), len));
                Ok(Value::Nil)
            }
            Verdict::Keep => {
                // Grown as the data arrives: a truncated stream costs what it holds.
                let mut data = Vec::with_capacity(len.min(1 << 20) as usize);
                let n = (&mut self.rd).take(len).read_to_end(&mut data)? as u64;
                self.pos += n;
                if n < len {
                    return Err(Fail::Io(std::io::ErrorKind::UnexpectedEof.into()));
                }
                Ok(match (kind, ext_type) {
                    (PayloadKind::String, _) => match String::from_utf8(data) {
                        Ok(s) => Value::from(s),
                        // Not text: held as bytes, which no key reading a string accepts.
                        Err(e) => Value::Binary(e.into_bytes()),
                    },
                    (PayloadKind::Extension, Some(t)) => Value::Ext(t, data),
                    _ => Value::Binary(data),
                })
            }
        }
    }
}

/// What a value is, for messages.
fn kind_of(value: &Value) -> &'static str {
    match value {
        Value::Nil => "nil",
        Value::Boolean(_) => "a boolean",
        Value::Integer(_) => "an integer",
        Value::F32(_) | Value::F64(_) => "a number",
        Value::String(_) => "a string",
        Value::Binary(_) => "binary data",
        Value::Array(_) => "an array",
        Value::Map(_) => "a map",
        Value::Ext(..) => "an extension value",
    }
}
