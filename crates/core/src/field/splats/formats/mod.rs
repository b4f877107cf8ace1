//! The files splats come in, and which reader takes each.
//!
//! Every reader yields the same activated [`Splats`] the INRIA PLY reader yields, plus a
//! [`SplatSource`] saying what the file was (format, version, how it was quantised, whether it
//! announces the antialiased mode) for `nerfx info` and the scene. The file is recognised by
//! its first bytes where it has a signature (`ply`, a zip's `PK`, SPZ's `NGSP` or gzip), and by
//! its name where it has none (`.splat`, a SOG folder's `meta.json`).
//!
//! - antimatter15 `.splat`: [`splat`]; SuperSplat's compressed PLY: [`compressed_ply`];
//!   Niantic's SPZ: [`spz`]; PlayCanvas's SOG: [`sog`].

pub(super) mod compressed_ply;
pub(super) mod sog;
pub(super) mod splat;
pub(super) mod spz;

use std::fmt;
use std::io::Read;
use std::path::Path;

use super::{splatfacto, Splats};
use crate::error::{Error, Result};

/// A splat file's format.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SplatFormat {
    /// The INRIA 3DGS PLY: float properties per splat.
    #[default]
    InriaPly,
    /// SuperSplat's compressed PLY: per-chunk ranges and packed 32-bit words.
    CompressedPly,
    /// antimatter15's `.splat`: 32-byte records.
    Splat,
    /// Niantic's SPZ.
    Spz,
    /// PlayCanvas's SOG: `meta.json` and WebP images, zipped (`.sog`) or in a folder.
    Sog,
    /// A nerfstudio splatfacto run's checkpoint.
    Splatfacto,
    /// Made in memory (benchmarks, tests).
    Generated,
}

impl fmt::Display for SplatFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            SplatFormat::InriaPly => "INRIA 3DGS PLY",
            SplatFormat::CompressedPly => "SuperSplat compressed PLY",
            SplatFormat::Splat => "antimatter15 .splat",
            SplatFormat::Spz => "Niantic SPZ",
            SplatFormat::Sog => "PlayCanvas SOG",
            SplatFormat::Splatfacto => "nerfstudio splatfacto checkpoint",
            SplatFormat::Generated => "generated",
        })
    }
}

/// What a splat file was: its format and version, how its values were quantised, and what it
/// announces about how it was trained.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SplatSource {
    /// The format.
    pub format: SplatFormat,
    /// The format's version where it has one (SPZ 2–4, SOG 1–2).
    pub version: Option<u32>,
    /// How positions, rotations, scales, opacities and colours were stored, for people.
    pub(crate) quantisation: String,
    /// Whether the file says the splats were trained in the antialiased (mip-splatting) mode:
    /// SPZ's flag, SOG's `model`, a PLY's `SplatRenderMode: mip` or `antialiased 1` comment.
    pub antialiased: bool,
    /// Anything else the artist should know about how the file was read.
    pub(crate) notes: Vec<String>,
}

/// Reads the splat file (or SOG folder, or splatfacto run) at `path`, whatever its format.
pub(super) fn load(path: &Path) -> Result<Splats> {
    if path.is_dir() {
        let meta = path.join("meta.json");
        if meta.is_file() {
            return sog::read_folder(&meta);
        }
        return splatfacto::read(path);
    }
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    let extension = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    if name == "meta.json" || name.ends_with(".meta.json") {
        return sog::read_folder(path);
    }
    if extension.as_deref() == Some("yml") {
        return splatfacto::read(path.parent().unwrap_or(Path::new(".")));
    }
    let magic = read_magic(path)?;
    match magic {
        [b'p', b'l', b'y', b'\n' | b'\r'] => super::ply::read(path),
        [b'P', b'K', 3, 4] => sog::read_zip(path),
        [b'N', b'G', b'S', b'P'] | [0x1f, 0x8b, _, _] => spz::read(path),
        _ if extension.as_deref() == Some("splat") => splat::read(path),
        _ => {
            let what = match extension.as_deref() {
                Some("spz") => "not an SPZ file (neither gzip nor an 'NGSP' header)",
                Some("sog") => "not a SOG file (not a zip archive)",
                Some("ply") => "not a PLY file (it does not start with 'ply')",
                _ => "not a splat file",
            };
            Err(Error::Unsupported(format!(
                "{}: {what}; splats are read from an INRIA or compressed .ply, a .splat, an \
                 .spz, a .sog or a SOG folder's meta.json, or a splatfacto run",
                path.display()
            )))
        }
    }
}

/// The first four bytes of the regular file at `path` (zeros past its end).
fn read_magic(path: &Path) -> Result<[u8; 4]> {
    let (file, _) = crate::input::open_regular(path)?;
    let mut magic = [0u8; 4];
    let mut got = 0;
    let mut file = file.take(4);
    while got < 4 {
        match file.read(&mut magic[got..]) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(Error::io(path, e)),
        }
    }
    Ok(magic)
}

/// The spherical-harmonics DC factor `Y₀⁰ = 1 / (2√π)`: a colour `c` displayed by a viewer
/// is the coefficient `(c − 0.5) / Y₀⁰`.
pub(super) const SH_C0: f32 = 0.282_094_8;

/// The DC coefficient that displays as colour `c` (0–1).
#[inline]
pub(super) fn dc_from_color(c: f32) -> f32 {
    (c - 0.5) / SH_C0
}

/// The SH degree of `n` higher coefficients per channel (0, 3, 8, 15).
pub(super) fn degree_of_rest(n: usize) -> Option<u8> {
    match n {
        0 => Some(0),
        3 => Some(1),
        8 => Some(2),
        15 => Some(3),
        _ => None,
    }
}

/// Whether PLY header comments announce the antialiased mode: Brush's and SuperSplat's
/// `SplatRenderMode: mip` (`default` and `2dgs` are not), Postshot's `antialiased 1`
/// (`antialiased 0` is not); the last such comment decides, matching is case-insensitive.
pub(super) fn antialiased_from_comments(comments: &[String]) -> bool {
    let mut antialiased = false;
    for comment in comments {
        let lower = comment.trim().to_ascii_lowercase();
        if let Some(mode) = lower.strip_prefix("splatrendermode:") {
            match mode.trim() {
                "mip" => antialiased = true,
                "default" | "2dgs" => antialiased = false,
                _ => {}
            }
        } else if let Some(value) = lower.strip_prefix("antialiased ") {
            match value.trim() {
                "1" => antialiased = true,
                "0" => antialiased = false,
                _ => {}
            }
        }
    }
    antialiased
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn render_mode_comments_decide_the_antialiased_mode_last_one_winning() {
        let c = |lines: &[&str]| lines.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        assert!(antialiased_from_comments(&c(&["SplatRenderMode: mip"])));
        assert!(antialiased_from_comments(&c(&["splatrendermode:   MIP "])));
        assert!(!antialiased_from_comments(&c(&[
            "SplatRenderMode: default"
        ])));
        assert!(antialiased_from_comments(&c(&["antialiased 1"])));
        assert!(!antialiased_from_comments(&c(&[
            "SplatRenderMode: mip",
            "antialiased 0"
        ])));
        assert!(!antialiased_from_comments(&c(&["made by a tool", "mip"])));
    }

    #[test]
    fn files_without_a_known_signature_are_refused_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("scan.spz");
        std::fs::write(&path, b"hello world").unwrap();
        let e = load(&path).unwrap_err().to_string();
        assert!(
            e.contains("scan.spz") && e.contains("not an SPZ file"),
            "{e}"
        );
        let path = dir.path().join("scan.xyz");
        std::fs::write(&path, b"hello world").unwrap();
        let e = load(&path).unwrap_err().to_string();
        assert!(e.contains("not a splat file"), "{e}");
    }
}
