//! The PLY container (binary, either byte order): the header's elements and their scalar
//! properties, and typed access to one element's rows.
//!
//! Only what splat files need is read: elements of scalar properties. A list property (a mesh's
//! faces) can only be skipped by reading it, so an element holding one is accepted only after
//! the element asked for. ASCII PLY is refused: splat tools write binary.
//!
//! Every count in the header is checked against the bytes the file really holds before anything
//! is allocated from it.

use std::path::Path;

use crate::error::{Error, Result};

/// Longest header read: real headers are a few kilobytes.
const MAX_HEADER: usize = 1 << 20;

/// A scalar property type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
}

/// One property of an element: its name, type and byte offset in a row.
#[derive(Clone, Debug)]
pub(crate) struct Property {
    pub name: String,
    pub(crate) kind: Scalar,
    offset: usize,
    /// A list property: rows of its element have no fixed size.
    list: bool,
}

/// An element: a name, a row count and its properties.
#[derive(Clone, Debug)]
pub(crate) struct Element {
    pub name: String,
    pub(crate) count: u64,
    pub properties: Vec<Property>,
    row_bytes: usize,
}

impl Element {
    fn has_list(&self) -> bool {
        self.properties.iter().any(|p| p.list)
    }

    /// The property called `name`.
    pub(crate) fn property(&self, name: &str) -> Option<&Property> {
        self.properties.iter().find(|p| p.name == name)
    }
}

/// A parsed header over the file's bytes.
pub(crate) struct Ply<'a> {
    path: &'a Path,
    bytes: &'a [u8],
    big_endian: bool,
    pub(crate) elements: Vec<Element>,
    /// The header's `comment` lines, without the keyword (SuperSplat announces its render mode
    /// in one).
    pub(crate) comments: Vec<String>,
    body: usize,
}

/// One element's rows, with fixed offsets.
pub(crate) struct Rows<'a> {
    data: &'a [u8],
    row_bytes: usize,
    big_endian: bool,
}

impl Rows<'_> {
    /// Rows held.
    pub fn len(&self) -> usize {
        self.data.len() / self.row_bytes.max(1)
    }

    /// Property `p` of row `row` as f32 (integers converted).
    #[inline]
    pub fn get(&self, row: usize, p: &Property) -> f32 {
        let at = row * self.row_bytes + p.offset;
        let b = &self.data[at..at + p.kind.size()];
        macro_rules! read {
            ($t:ty, $n:literal) => {{
                let mut a = [0u8; $n];
                a.copy_from_slice(b);
                if self.big_endian {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }
            }};
        }
        match p.kind {
            Scalar::I8 => b[0] as i8 as f32,
            Scalar::U8 => b[0] as f32,
            Scalar::I16 => read!(i16, 2) as f32,
            Scalar::U16 => read!(u16, 2) as f32,
            Scalar::I32 => read!(i32, 4) as f32,
            Scalar::U32 => read!(u32, 4) as f32,
            Scalar::F32 => read!(f32, 4),
            Scalar::F64 => read!(f64, 8) as f32,
        }
    }

    /// Property `p` of row `row` as its bits, for packed integer words (`u32`, `u8`…, read
    /// exactly; floats give their bit pattern).
    #[inline]
    pub(crate) fn bits(&self, row: usize, p: &Property) -> u32 {
        let at = row * self.row_bytes + p.offset;
        let b = &self.data[at..at + p.kind.size()];
        let mut a = [0u8; 4];
        match p.kind.size() {
            1 => return u32::from(b[0]),
            2 => a[..2].copy_from_slice(b),
            4 => a.copy_from_slice(b),
            _ => return self.get(row, p).to_bits(),
        }
        match (self.big_endian, p.kind.size()) {
            (true, 2) => u32::from(u16::from_be_bytes([a[0], a[1]])),
            (false, 2) => u32::from(u16::from_le_bytes([a[0], a[1]])),
            (true, _) => u32::from_be_bytes(a),
            (false, _) => u32::from_le_bytes(a),
        }
    }
}

impl<'a> Ply<'a> {
    /// Parses the header of `bytes` (the whole file; `path` for messages).
    pub fn parse(path: &'a Path, bytes: &'a [u8]) -> Result<Ply<'a>> {
        let bad = |at: String, msg: String| Error::format(path, at, msg);
        if !bytes.starts_with(b"ply\n") && !bytes.starts_with(b"ply\r\n") {
            return Err(bad(
                "header".into(),
                "not a PLY file (it does not start with 'ply')".into(),
            ));
        }
        let search = &bytes[..bytes.len().min(MAX_HEADER)];
        let end = find(search, b"end_header\n")
            .map(|i| i + b"end_header\n".len())
            .or_else(|| find(search, b"end_header\r\n").map(|i| i + b"end_header\r\n".len()))
            .ok_or_else(|| {
                bad(
                    "header".into(),
                    format!("no 'end_header' line in the first {MAX_HEADER} bytes"),
                )
            })?;
        let header = std::str::from_utf8(&bytes[..end])
            .map_err(|_| bad("header".into(), "is not text".into()))?;
        let mut big_endian = None;
        let mut elements: Vec<Element> = Vec::new();
        let mut comments = Vec::new();
        for (n, line) in header.lines().enumerate().skip(1) {
            let at = || format!("header line {}", n + 1);
            let words: Vec<&str> = line.split_whitespace().collect();
            match words.as_slice() {
                ["comment", ..] => {
                    let text = line.trim_start().strip_prefix("comment").unwrap_or("");
                    comments.push(text.trim().to_string());
                }
                [] | ["obj_info", ..] | ["end_header"] => {}
                ["format", kind, _version] => {
                    big_endian = Some(match *kind {
                        "binary_little_endian" => false,
                        "binary_big_endian" => true,
                        "ascii" => {
                            return Err(bad(
                                at(),
                                "ASCII PLY is not read; save the splats as binary PLY \
                                 (what 3DGS, gsplat and ns-export write)"
                                    .into(),
                            ))
                        }
                        other => return Err(bad(at(), format!("unknown format '{other}'"))),
                    })
                }
                ["element", name, count] => {
                    let count: u64 = count.parse().map_err(|_| {
                        bad(
                            at(),
                            format!("element '{name}': count '{count}' is not a number"),
                        )
                    })?;
                    elements.push(Element {
                        name: name.to_string(),
                        count,
                        properties: Vec::new(),
                        row_bytes: 0,
                    });
                }
                ["property", "list", count, item, name] => {
                    let el = elements
                        .last_mut()
                        .ok_or_else(|| bad(at(), "a property before any element".into()))?;
                    for t in [count, item] {
                        Scalar::parse(t)
                            .ok_or_else(|| bad(at(), format!("unknown property type '{t}'")))?;
                    }
                    el.properties.push(Property {
                        name: name.to_string(),
                        kind: Scalar::U8,
                        offset: 0,
                        list: true,
                    });
                }
                ["property", kind, name] => {
                    let el = elements
                        .last_mut()
                        .ok_or_else(|| bad(at(), "a property before any element".into()))?;
                    let kind = Scalar::parse(kind)
                        .ok_or_else(|| bad(at(), format!("unknown property type '{kind}'")))?;
                    el.properties.push(Property {
                        name: name.to_string(),
                        kind,
                        offset: el.row_bytes,
                        list: false,
                    });
                    el.row_bytes += kind.size();
                }
                _ => return Err(bad(at(), format!("cannot read '{line}'"))),
            }
        }
        let big_endian =
            big_endian.ok_or_else(|| bad("header".into(), "no 'format' line".into()))?;
        Ok(Ply {
            path,
            bytes,
            big_endian,
            elements,
            comments,
            body: end,
        })
    }

    /// The element called `name` and its rows, after checking that the file holds them all.
    pub fn rows(&self, name: &str) -> Result<(&Element, Rows<'a>)> {
        let mut start = self.body as u64;
        for el in &self.elements {
            if el.name == name {
                if el.has_list() {
                    return Err(Error::format(
                        self.path,
                        format!("element '{name}'"),
                        "has a list property; expected scalar properties only",
                    ));
                }
                let need = el.count.checked_mul(el.row_bytes as u64);
                let have = self.bytes.len() as u64 - start;
                return match need {
                    Some(need) if need <= have => Ok((
                        el,
                        Rows {
                            data: &self.bytes[start as usize..(start + need) as usize],
                            row_bytes: el.row_bytes,
                            big_endian: self.big_endian,
                        },
                    )),
                    _ => Err(Error::format(
                        self.path,
                        format!("element '{name}'"),
                        format!(
                            "the header declares {} rows of {} bytes but the file holds {have} \
                             bytes after the header (truncated?)",
                            el.count, el.row_bytes
                        ),
                    )),
                };
            }
            if el.has_list() {
                return Err(Error::format(
                    self.path,
                    format!("element '{}'", el.name),
                    format!(
                        "has a list property and comes before '{name}'; cannot skip it to reach \
                         '{name}'"
                    ),
                ));
            }
            start = el
                .count
                .checked_mul(el.row_bytes as u64)
                .and_then(|n| n.checked_add(start))
                .filter(|&end| end <= self.bytes.len() as u64)
                .ok_or_else(|| {
                    Error::format(
                        self.path,
                        format!("element '{}'", el.name),
                        "declares more rows than the file holds (truncated?)",
                    )
                })?;
        }
        Err(Error::format(
            self.path,
            "header",
            format!("no '{name}' element"),
        ))
    }
}

fn find(haystack: &[u8], needle: &[u8]) -> Option<usize> {
    haystack.windows(needle.len()).position(|w| w == needle)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file(header: &str, body: &[u8]) -> Vec<u8> {
        let mut v = header.as_bytes().to_vec();
        v.extend_from_slice(body);
        v
    }

    #[test]
    fn reads_typed_properties_at_their_offsets_in_either_byte_order() {
        let path = Path::new("t.ply");
        let mut le = Vec::new();
        le.push(200u8);
        le.extend_from_slice(&(-3i16).to_le_bytes());
        le.extend_from_slice(&1.5f32.to_le_bytes());
        le.extend_from_slice(&2.25f64.to_le_bytes());
        let h = "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty uchar a\n\
                 property short b\nproperty float c\nproperty double d\nend_header\n";
        let bytes = file(h, &le);
        let ply = Ply::parse(path, &bytes).unwrap();
        let (el, rows) = ply.rows("vertex").unwrap();
        let got: Vec<f32> = ["a", "b", "c", "d"]
            .iter()
            .map(|n| rows.get(0, el.property(n).unwrap()))
            .collect();
        assert_eq!(got, [200.0, -3.0, 1.5, 2.25]);

        let mut be = vec![200u8];
        be.extend_from_slice(&(-3i16).to_be_bytes());
        be.extend_from_slice(&1.5f32.to_be_bytes());
        be.extend_from_slice(&2.25f64.to_be_bytes());
        let bytes = file(&h.replace("little", "big"), &be);
        let ply = Ply::parse(path, &bytes).unwrap();
        let (el, rows) = ply.rows("vertex").unwrap();
        assert_eq!(rows.get(0, el.property("d").unwrap()), 2.25);
    }

    #[test]
    fn skips_scalar_elements_before_the_one_asked_for() {
        let h = "ply\nformat binary_little_endian 1.0\nelement extra 2\nproperty int i\n\
                 element vertex 1\nproperty float x\nelement face 1\n\
                 property list uchar int vertex_indices\nend_header\n";
        let mut body = vec![0u8; 8];
        body.extend_from_slice(&7.0f32.to_le_bytes());
        body.extend_from_slice(&[3, 0, 0, 0, 0]);
        let bytes = file(h, &body);
        let ply = Ply::parse(Path::new("t.ply"), &bytes).unwrap();
        let (el, rows) = ply.rows("vertex").unwrap();
        assert_eq!(rows.len(), 1);
        assert_eq!(rows.get(0, el.property("x").unwrap()), 7.0);
    }

    #[test]
    fn refuses_what_it_cannot_read_with_the_reason() {
        let p = Path::new("scan.ply");
        let err = |bytes: &[u8]| match Ply::parse(p, bytes)
            .and_then(|ply| ply.rows("vertex").map(|_| ()))
        {
            Err(e) => e.to_string(),
            Ok(()) => panic!("accepted"),
        };
        assert!(err(b"").contains("not a PLY"));
        assert!(err(b"ply\nformat ascii 1.0\nend_header\n").contains("ASCII"));
        assert!(
            err(b"ply\nformat binary_little_endian 1.0\nelement vertex 3\n").contains("end_header")
        );
        let huge = "ply\nformat binary_little_endian 1.0\nelement vertex 1099511627776\n\
                    property float x\nend_header\n";
        let e = err(huge.as_bytes());
        assert!(e.contains("scan.ply") && e.contains("truncated"), "{e}");
        let overflow =
            "ply\nformat binary_little_endian 1.0\nelement vertex 18446744073709551615\n\
                        property double x\nend_header\n";
        assert!(err(overflow.as_bytes()).contains("truncated"));
        let list_first = "ply\nformat binary_little_endian 1.0\nelement face 1\n\
                          property list uchar int i\nelement vertex 0\nproperty float x\nend_header\n";
        assert!(err(list_first.as_bytes()).contains("list property"));
        assert!(
            err(b"ply\nformat binary_little_endian 1.0\nelement face 0\nend_header\n")
                .contains("no 'vertex' element")
        );
        assert!(err(b"ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty half x\nend_header\n")
            .contains("unknown property type 'half'"));
    }
}
