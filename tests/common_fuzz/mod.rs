//! A small deterministic mutator for the fuzz harness: from a seed and valid inputs it makes
//! hostile variants the way the formats break in practice — flipped bits, inserted and
//! deleted bytes, truncation, splices of two inputs, numbers in text replaced by extreme
//! ones, length fields of msgpack, pickle and zip set huge, floats in binary data replaced
//! by NaN, infinities and extremes. The same seed always gives the same bytes.
// The fuzz binary is its only user; not every helper is used by every target.
#![allow(dead_code)]

use super::common_fields::SplitMix64;

/// How an input is structured, for the mutations that know its framing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// JSON, YAML: numbers are replaced as text.
    Text,
    /// msgpack: its str/bin/array/map length fields are set huge, its numbers extreme.
    Msgpack,
    /// gzip-framed msgpack: as [`Kind::Msgpack`] inside the framing, or bytes of the stream.
    GzipMsgpack,
    /// A Python pickle: its length-prefixed opcodes and integers are set huge.
    Pickle,
    /// A zip archive: its size, count and offset fields are set huge.
    Zip,
    /// PLY: a text header (numbers replaced as text) then little-endian floats.
    Ply,
    /// Anything else: bytes only.
    Bytes,
}

/// Numbers that break parsers: huge, tiny, negative, zero, not finite, past every integer
/// type, and the spellings of NaN and infinity that Python and C write.
const NUMBERS: &[&str] = &[
    "1e308",
    "-1e308",
    "1e309",
    "NaN",
    "nan",
    "Infinity",
    "-Infinity",
    "inf",
    "0",
    "-0",
    "-1",
    "1e-320",
    "4294967296",
    "18446744073709551616",
    "9223372036854775807",
    "-9223372036854775808",
    "2147483647",
    "1000000000",
    "0.5",
    "1",
    "2",
    "-0.5",
    "0.001",
    "100",
];

/// Floats written over binary data.
const FLOATS: &[f32] = &[
    f32::NAN,
    f32::INFINITY,
    f32::NEG_INFINITY,
    f32::MAX,
    -f32::MAX,
    1e-45,
    0.0,
    -0.0,
    1e30,
];

/// One mutated variant of `inputs[which]`: one to four mutations drawn by `rng`, the others
/// of `inputs` available for splices. Three cases in five of a structured kind keep to its
/// structure (numbers, floats, length fields), so that most of them get past the syntax to
/// the code that uses the values.
pub fn mutate(rng: &mut SplitMix64, inputs: &[Vec<u8>], which: usize, kind: Kind) -> Vec<u8> {
    let mut bytes = inputs[which].clone();
    let structured = kind != Kind::Bytes && rng.below(5) < 3;
    if kind == Kind::GzipMsgpack {
        if !structured {
            return mutate(rng, inputs, which, Kind::Bytes);
        }
        // The document inside the framing, mutated as msgpack and framed again.
        if let Some(inner) = gunzip(&bytes) {
            return gzip(&mutate(rng, &[inner], 0, Kind::Msgpack));
        }
    }
    let rounds = 1 + rng.below(4);
    for _ in 0..rounds {
        if !(structured && mutate_structure(rng, &mut bytes, kind)) {
            mutate_once(rng, &mut bytes, inputs, kind);
        }
    }
    bytes
}

/// One mutation that knows `kind`'s structure; false when `b` offers it nothing to change.
fn mutate_structure(rng: &mut SplitMix64, b: &mut Vec<u8>, kind: Kind) -> bool {
    match kind {
        Kind::Text => replace_number(rng, b),
        Kind::Msgpack => extreme_msgpack_field(rng, b),
        Kind::Pickle => huge_pickle_field(rng, b),
        Kind::Zip => huge_zip_field(rng, b),
        Kind::Ply => {
            if rng.below(2) == 0 {
                replace_number(rng, b)
            } else {
                replace_float(rng, b)
            }
        }
        Kind::GzipMsgpack | Kind::Bytes => false,
    }
}

fn mutate_once(rng: &mut SplitMix64, b: &mut Vec<u8>, inputs: &[Vec<u8>], kind: Kind) {
    // Structure-aware mutations half the time where the kind has any.
    if kind != Kind::Bytes && rng.below(2) == 0 && mutate_structure(rng, b, kind) {
        return;
    }
    let len = b.len() as u64;
    match rng.below(7) {
        0 | 1 if len > 0 => {
            let i = rng.below(len) as usize;
            b[i] ^= 1 << rng.below(8);
        }
        2 if len > 0 => {
            let i = rng.below(len) as usize;
            b[i] = [0x00, 0xff, 0x7f, 0x80, b'"', b'{', b'[', b'\n'][rng.below(8) as usize];
        }
        3 => {
            let i = rng.below(len + 1) as usize;
            let n = 1 + rng.below(8) as usize;
            let fill: Vec<u8> = (0..n).map(|_| rng.next_u64() as u8).collect();
            b.splice(i..i, fill);
        }
        4 if len > 0 => {
            let i = rng.below(len) as usize;
            let n = (1 + rng.below(16) as usize).min(b.len() - i);
            b.drain(i..i + n);
        }
        5 => {
            let keep = rng.below(len + 1) as usize;
            b.truncate(keep);
        }
        _ => splice(rng, b, inputs),
    }
}

/// The head of `b` up to a random point, then the tail of another input from a random point.
fn splice(rng: &mut SplitMix64, b: &mut Vec<u8>, inputs: &[Vec<u8>]) {
    let other = &inputs[rng.below(inputs.len() as u64) as usize];
    let cut = rng.below(b.len() as u64 + 1) as usize;
    let from = rng.below(other.len() as u64 + 1) as usize;
    b.truncate(cut);
    b.extend_from_slice(&other[from..]);
}

/// Replaces one number written as text (a run of digits, with its sign, point and exponent)
/// by one of [`NUMBERS`]; false when `b` holds none.
fn replace_number(rng: &mut SplitMix64, b: &mut Vec<u8>) -> bool {
    // Only the text part of a PLY: up to its end_header.
    let end = find(b, b"end_header").unwrap_or(b.len());
    let mut spans = Vec::new();
    let mut i = 0;
    while i < end {
        if b[i].is_ascii_digit() {
            let mut s = i;
            if s > 0 && b[s - 1] == b'-' {
                s -= 1;
            }
            let mut e = i;
            while e < end && (b[e].is_ascii_digit() || b"+-.eE".contains(&b[e])) {
                e += 1;
            }
            spans.push((s, e));
            i = e;
        } else {
            i += 1;
        }
    }
    if spans.is_empty() {
        return false;
    }
    let (s, e) = spans[rng.below(spans.len() as u64) as usize];
    let number = NUMBERS[rng.below(NUMBERS.len() as u64) as usize];
    b.splice(s..e, number.bytes());
    true
}

/// Writes one of [`FLOATS`] at a 4-byte-aligned place of a PLY's binary body.
fn replace_float(rng: &mut SplitMix64, b: &mut [u8]) -> bool {
    let Some(header) = find(b, b"end_header\n").map(|i| i + 11) else {
        return false;
    };
    let slots = (b.len() - header) / 4;
    if slots == 0 {
        return false;
    }
    let at = header + 4 * rng.below(slots as u64) as usize;
    let v = FLOATS[rng.below(FLOATS.len() as u64) as usize];
    b[at..at + 4].copy_from_slice(&v.to_le_bytes());
    true
}

/// `(offset, width)` of lengths and `(offset, marker)` of numbers: see [`msgpack_fields`].
type MsgpackFields = (Vec<(usize, usize)>, Vec<(usize, u8)>);

/// Where the fields of a msgpack document are: `(offset, width)` of every explicit length
/// (str8–32, bin8–32, array16/32, map16/32) and `(offset, marker)` of every number that has
/// bytes of its own (floats and sized integers). A linear walk: containers' elements follow
/// their header, strings' and binaries' payloads are skipped. It stops where the bytes stop
/// being msgpack (after earlier mutations).
fn msgpack_fields(b: &[u8]) -> MsgpackFields {
    let (mut lengths, mut numbers) = (Vec::new(), Vec::new());
    let mut i = 0;
    let be = |at: usize, w: usize| -> Option<usize> {
        let bytes = b.get(at..at + w)?;
        Some(bytes.iter().fold(0usize, |n, &x| (n << 8) | usize::from(x)))
    };
    while i < b.len() {
        let m = b[i];
        let next = match m {
            0x00..=0x9f | 0xc0..=0xc3 | 0xe0..=0xff => Some(i + 1),
            0xa0..=0xbf => Some(i + 1 + usize::from(m & 0x1f)),
            0xc4..=0xc6 | 0xd9..=0xdb => {
                let w = match m {
                    0xc4 | 0xd9 => 1,
                    0xc5 | 0xda => 2,
                    _ => 4,
                };
                lengths.push((i + 1, w));
                be(i + 1, w).map(|n| i + 1 + w + n)
            }
            0xc7..=0xc9 => {
                let w = 1 << (m - 0xc7);
                lengths.push((i + 1, w));
                be(i + 1, w).map(|n| i + 2 + w + n)
            }
            0xca..=0xd3 => {
                numbers.push((i, m));
                let w = match m {
                    0xca => 4,
                    0xcb => 8,
                    _ => 1 << ((m - 0xcc) % 4),
                };
                Some(i + 1 + w)
            }
            0xd4..=0xd8 => Some(i + 2 + (1 << (m - 0xd4))),
            0xdc..=0xdf => {
                let w = if m.is_multiple_of(2) { 2 } else { 4 };
                lengths.push((i + 1, w));
                Some(i + 1 + w)
            }
        };
        match next {
            Some(n) if n > i => i = n,
            _ => break,
        }
    }
    lengths.retain(|&(at, w)| at + w <= b.len());
    (lengths, numbers)
}

/// Sets the length of one msgpack str/bin/array/map to a huge value, or one of its numbers to
/// an extreme one (NaN, infinity, the float's largest, the integer's largest).
fn extreme_msgpack_field(rng: &mut SplitMix64, b: &mut [u8]) -> bool {
    let (lengths, numbers) = msgpack_fields(b);
    if !numbers.is_empty() && (lengths.is_empty() || rng.below(2) == 0) {
        let (at, m) = numbers[rng.below(numbers.len() as u64) as usize];
        let v = FLOATS[rng.below(FLOATS.len() as u64) as usize];
        let bytes: Vec<u8> = match m {
            0xca => v.to_be_bytes().to_vec(),
            0xcb => f64::from(v).to_be_bytes().to_vec(),
            _ => {
                let w = 1usize << ((m - 0xcc) % 4);
                vec![if rng.below(2) == 0 { 0xff } else { 0x7f }; w]
            }
        };
        if let Some(dst) = b.get_mut(at + 1..at + 1 + bytes.len()) {
            dst.copy_from_slice(&bytes);
            return true;
        }
        return false;
    }
    if lengths.is_empty() {
        return false;
    }
    let (at, w) = lengths[rng.below(lengths.len() as u64) as usize];
    let value = huge(rng, w);
    // msgpack lengths are big-endian.
    b[at..at + w].copy_from_slice(&value.to_be_bytes()[8 - w..]);
    true
}

/// Sets a pickle opcode's length or integer argument to a huge value: BINUNICODE (`X`),
/// BINBYTES (`B`), SHORT_BINUNICODE (0x8c), SHORT_BINBYTES (`C`), BINUNICODE8 (0x8d),
/// BININT (`J`), BININT1 (`K`), BININT2 (`M`), LONG1 (0x8a), FRAME (0x95).
fn huge_pickle_field(rng: &mut SplitMix64, b: &mut [u8]) -> bool {
    let width = |m: u8| match m {
        0x8c | b'C' | b'K' | 0x8a => 1,
        b'M' => 2,
        b'X' | b'B' | b'J' => 4,
        0x8d | 0x95 => 8,
        _ => 0,
    };
    let at: Vec<usize> = (0..b.len())
        .filter(|&i| width(b[i]) > 0 && i + width(b[i]) < b.len())
        .collect();
    if at.is_empty() {
        return false;
    }
    let i = at[rng.below(at.len() as u64) as usize];
    let w = width(b[i]);
    let value = huge(rng, w);
    // Pickle arguments are little-endian.
    b[i + 1..i + 1 + w].copy_from_slice(&value.to_le_bytes()[..w]);
    true
}

/// Sets a size, count or offset field of a zip's local header, central directory entry or
/// end record to a huge value.
fn huge_zip_field(rng: &mut SplitMix64, b: &mut [u8]) -> bool {
    // (signature, offsets of 4-byte fields, offsets of 2-byte fields) from the record start.
    const RECORDS: [(&[u8; 4], &[usize], &[usize]); 3] = [
        (b"PK\x03\x04", &[18, 22], &[26, 28]),
        (b"PK\x01\x02", &[20, 24, 42], &[28, 30, 32]),
        (b"PK\x05\x06", &[12, 16], &[8, 10, 20]),
    ];
    let mut fields = Vec::new();
    for (sig, fours, twos) in RECORDS {
        for i in (0..b.len().saturating_sub(3)).filter(|&i| &b[i..i + 4] == sig) {
            fields.extend(fours.iter().map(|o| (i + o, 4)));
            fields.extend(twos.iter().map(|o| (i + o, 2)));
        }
    }
    fields.retain(|&(at, w)| at + w <= b.len());
    if fields.is_empty() {
        return false;
    }
    let (at, w) = fields[rng.below(fields.len() as u64) as usize];
    let value = huge(rng, w);
    b[at..at + w].copy_from_slice(&value.to_le_bytes()[..w]);
    true
}

/// A huge value for a field `width` bytes wide: all ones, the signed maximum, or just past
/// the data (a few thousand).
fn huge(rng: &mut SplitMix64, width: usize) -> u64 {
    let all = if width >= 8 {
        u64::MAX
    } else {
        (1u64 << (8 * width)) - 1
    };
    match rng.below(3) {
        0 => all,
        1 => all >> 1,
        _ => 4096 + rng.below(1 << 20).min(all),
    }
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

fn gunzip(b: &[u8]) -> Option<Vec<u8>> {
    let mut out = Vec::new();
    std::io::Read::read_to_end(&mut flate2::read::GzDecoder::new(b), &mut out).ok()?;
    Some(out)
}

fn gzip(b: &[u8]) -> Vec<u8> {
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    std::io::Write::write_all(&mut enc, b).expect("writing to memory");
    enc.finish().expect("writing to memory")
}
