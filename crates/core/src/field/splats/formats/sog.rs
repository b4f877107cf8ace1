//! PlayCanvas's SOG (what SuperSplat and splat-transform publish for the web): a `meta.json`
//! and lossless WebP images holding one splat a pixel, row by row. Version 2 zips them into
//! one `.sog` (or leaves them in a folder); version 1 (no `version` in `meta.json`) is a folder.
//!
//! - Means: two images, the low and high bytes of 16-bit fractions of x, y, z between
//!   `means.mins` and `means.maxs` (a zero range counts as 1); each is the log transform
//!   `sign(v)·ln(|v| + 1)` of the position, undone as `sign(t)·(e^|t| − 1)`.
//! - Quaternions: r, g, b the three smaller components `(b/255·2 − 1)/√2` and a = 252 + the
//!   index (`w x y z`) of the largest, which is `√(1 − rest)`; any other a reads as the
//!   identity, as PlayCanvas's reader does.
//! - Scales and `sh0`: version 2 looks bytes up in 256-entry codebooks (log scales; DC
//!   coefficients), `sh0`'s alpha is the opacity `a/255`; version 1 maps bytes linearly between
//!   per-channel `mins` and `maxs` (`sh0`'s fourth channel an opacity logit).
//! - `shN` (optional): a labels image (a 16-bit palette index in r, g a splat) and a centroids
//!   image of 64 palette entries a row, each `coefficients` pixels wide, whose r, g, b bytes are
//!   looked up in `shN.codebook` (version 2) or mapped between `shN.mins` and `shN.maxs`
//!   (version 1); labels past the palette give zeros.
//!
//! Each image's size is read from its header and checked against the splat count before it is
//! decoded, and each is decoded once.

use std::io::Cursor;
use std::path::{Path, PathBuf};

use glam::Vec3;
use serde::Deserialize;
use serde_json::Value;

use super::{degree_of_rest, SplatFormat};
use crate::error::{Error, Result};
use crate::field::container::Zip;
use crate::field::splats::{SplatColor, Splats};

/// The most pixels an image may have beyond the splats it holds: splat-transform's images are
/// the count rounded up to whole multiples of 4 in each side.
fn pixel_bound(count: usize) -> usize {
    count.saturating_mul(2).saturating_add(1 << 16)
}

/// Where the images are.
enum Store<'a> {
    Zip(&'a Zip),
    Folder(PathBuf),
}

impl Store<'_> {
    fn load(&self, meta: &Path, name: &str) -> Result<Vec<u8>> {
        match self {
            Store::Zip(zip) => zip.read(name)?.ok_or_else(|| {
                Error::format(meta, format!("image '{name}'"), "is not in the archive")
            }),
            Store::Folder(dir) => {
                let file = Path::new(name);
                if file.is_absolute() || file.components().count() != 1 {
                    return Err(Error::format(
                        meta,
                        format!("image '{name}'"),
                        "must be a file name next to meta.json",
                    ));
                }
                crate::input::read_bytes(&dir.join(file))
            }
        }
    }
}

/// Reads a `.sog` archive.
pub(crate) fn read_zip(path: &Path) -> Result<Splats> {
    let zip = Zip::open(path)?;
    from_zip(zip)
}

fn from_zip(zip: Zip) -> Result<Splats> {
    let path = zip.path().to_path_buf();
    let name = zip
        .names()
        .find(|n| *n == "meta.json")
        .map(str::to_string)
        .ok_or_else(|| Error::format(&path, "", "no 'meta.json' in the archive: not a SOG file"))?;
    let text = zip.read(&name)?.unwrap_or_default();
    decode(&path, &text, &Store::Zip(&zip))
}

/// Reads a SOG folder through its `meta.json`.
pub(crate) fn read_folder(meta: &Path) -> Result<Splats> {
    let text = crate::input::read_bytes(meta)?;
    let dir = meta.parent().unwrap_or(Path::new(".")).to_path_buf();
    decode(meta, &text, &Store::Folder(dir))
}

#[derive(Deserialize)]
struct Files {
    files: Vec<String>,
}

#[derive(Deserialize)]
struct MeansMeta {
    mins: [f32; 3],
    maxs: [f32; 3],
    files: Vec<String>,
}

#[derive(Deserialize)]
struct CodebookMeta {
    codebook: Vec<f32>,
    files: Vec<String>,
}

#[derive(Deserialize)]
struct ShNV2 {
    count: usize,
    bands: u8,
    codebook: Vec<f32>,
    files: Vec<String>,
}

#[derive(Deserialize)]
struct MetaV2 {
    count: usize,
    #[serde(default)]
    model: Option<String>,
    means: MeansMeta,
    scales: CodebookMeta,
    quats: Files,
    sh0: CodebookMeta,
    #[serde(default, rename = "shN")]
    sh_n: Option<ShNV2>,
}

#[derive(Deserialize)]
struct MeansV1 {
    shape: Vec<usize>,
    mins: [f32; 3],
    maxs: [f32; 3],
    files: Vec<String>,
}

#[derive(Deserialize)]
struct RangeV1 {
    mins: Vec<f32>,
    maxs: Vec<f32>,
    files: Vec<String>,
}

#[derive(Deserialize)]
struct ShNV1 {
    mins: f32,
    maxs: f32,
    files: Vec<String>,
}

#[derive(Deserialize)]
struct MetaV1 {
    means: MeansV1,
    scales: RangeV1,
    quats: Files,
    sh0: RangeV1,
    #[serde(default, rename = "shN")]
    sh_n: Option<ShNV1>,
}

/// A decoded image: RGBA bytes, row by row.
struct Image {
    width: usize,
    height: usize,
    rgba: Vec<u8>,
}

/// Decodes the WebP `name` after checking from its header that its size suits `count`
/// splats: at least `count` pixels (or exactly `width` wide, for a palette), at most
/// `most` pixels.
fn image(
    meta: &Path,
    store: &Store,
    name: &str,
    count: usize,
    width: Option<usize>,
    most: usize,
) -> Result<Image> {
    let what = format!("image '{name}'");
    let bytes = store.load(meta, name)?;
    let bad = |m: String| Error::format(meta, &what, m);
    let mut decoder = image_webp::WebPDecoder::new(Cursor::new(&bytes[..]))
        .map_err(|e| bad(format!("not a readable WebP image: {e}")))?;
    let (w, h) = decoder.dimensions();
    let (w, h) = (w as usize, h as usize);
    let pixels = w.saturating_mul(h);
    match width {
        Some(want) if w != want => {
            return Err(bad(format!(
                "{w} pixels wide; {want} expected for its palette"
            )))
        }
        _ if pixels < count => {
            return Err(bad(format!(
                "{w}×{h} holds {pixels} pixels, fewer than the {count} splats meta.json \
                 declares"
            )))
        }
        _ => {}
    }
    if pixels > most {
        return Err(bad(format!(
            "{w}×{h} is far larger than {count} splats need"
        )));
    }
    if decoder.is_lossy() {
        return Err(bad(
            "is lossy WebP; SOG images hold exact bytes and must be lossless".into(),
        ));
    }
    let size = decoder
        .output_buffer_size()
        .ok_or_else(|| bad("is too large".into()))?;
    let mut data = vec![0u8; size];
    decoder
        .read_image(&mut data)
        .map_err(|e| bad(format!("cannot be decoded: {e}")))?;
    let rgba = if decoder.has_alpha() {
        data
    } else {
        let mut rgba = Vec::with_capacity(pixels * 4);
        for p in data.chunks_exact(3) {
            rgba.extend_from_slice(&[p[0], p[1], p[2], 255]);
        }
        rgba
    };
    Ok(Image {
        width: w,
        height: h,
        rgba,
    })
}

/// The one or two file names an entry lists.
fn files<'a>(meta: &Path, entry: &str, files: &'a [String], want: usize) -> Result<&'a [String]> {
    if files.len() < want {
        return Err(Error::format(
            meta,
            format!("meta.json '{entry}.files'"),
            format!("lists {} images; {want} expected", files.len()),
        ));
    }
    Ok(&files[..want])
}

/// Checks that ranges and codebooks in `meta.json` are finite and not absurd.
fn check_values(meta: &Path, entry: &str, values: &[f32], limit: f32) -> Result<()> {
    if let Some((i, v)) = values
        .iter()
        .enumerate()
        .find(|(_, v)| !v.is_finite() || v.abs() > limit)
    {
        return Err(Error::format(
            meta,
            format!("meta.json '{entry}' value {i}"),
            format!("{v} is not a usable quantisation value"),
        ));
    }
    Ok(())
}

fn check_codebook(meta: &Path, entry: &str, codebook: &[f32], limit: f32) -> Result<()> {
    if codebook.is_empty() || codebook.len() > 256 {
        return Err(Error::format(
            meta,
            format!("meta.json '{entry}.codebook'"),
            format!("{} entries; 1 to 256 expected", codebook.len()),
        ));
    }
    check_values(meta, &format!("{entry}.codebook"), codebook, limit)
}

/// A codebook lookup, past its end an error naming the image and splat.
fn lookup(meta: &Path, image: &str, codebook: &[f32], byte: u8, splat: usize) -> Result<f32> {
    codebook.get(usize::from(byte)).copied().ok_or_else(|| {
        Error::format(
            meta,
            format!("image '{image}', splat {splat}"),
            format!(
                "byte {byte} is past the codebook's {} entries",
                codebook.len()
            ),
        )
    })
}

fn decode(meta: &Path, text: &[u8], store: &Store) -> Result<Splats> {
    let json: Value = serde_json::from_slice(text)
        .map_err(|e| Error::format(meta, "meta.json", format!("is not JSON: {e}")))?;
    match json.get("version") {
        None => {
            let m: MetaV1 = serde_json::from_value(json).map_err(|e| {
                Error::format(
                    meta,
                    "meta.json",
                    format!("not SOG version 1 metadata: {e}"),
                )
            })?;
            decode_v1(meta, m, store)
        }
        Some(v) if v.as_u64() == Some(2) => {
            let m: MetaV2 = serde_json::from_value(json).map_err(|e| {
                Error::format(
                    meta,
                    "meta.json",
                    format!("not SOG version 2 metadata: {e}"),
                )
            })?;
            decode_v2(meta, m, store)
        }
        Some(v) => Err(Error::Unsupported(format!(
            "{}: SOG version {v}; nerfx reads SOG versions 1 and 2",
            meta.display()
        ))),
    }
}

/// `sign(t)·(e^|t| − 1)`: the position whose log transform is `t`.
fn inverse_log(t: f32) -> f32 {
    let e = t.abs().exp() - 1.0;
    if t < 0.0 {
        -e
    } else {
        e
    }
}

/// The means from their two images.
fn means(
    meta: &Path,
    store: &Store,
    names: &[String],
    mins: [f32; 3],
    maxs: [f32; 3],
    count: usize,
) -> Result<Vec<Vec3>> {
    check_values(meta, "means.mins", &mins, 30.0)?;
    check_values(meta, "means.maxs", &maxs, 30.0)?;
    let lo = image(meta, store, &names[0], count, None, pixel_bound(count))?;
    let hi = image(meta, store, &names[1], count, None, pixel_bound(count))?;
    let span = |k: usize| {
        let s = maxs[k] - mins[k];
        if s == 0.0 {
            1.0
        } else {
            s
        }
    };
    let spans = [span(0), span(1), span(2)];
    Ok((0..count)
        .map(|i| {
            let at = 4 * i;
            let c = |k: usize| {
                let v = u16::from(lo.rgba[at + k]) | (u16::from(hi.rgba[at + k]) << 8);
                inverse_log(mins[k] + spans[k] * (f32::from(v) / 65535.0))
            };
            Vec3::new(c(0), c(1), c(2))
        })
        .collect())
}

/// A quaternion `w x y z` from its pixel.
fn quaternion(p: &[u8]) -> [f32; 4] {
    let tag = p[3];
    if !(252..=255).contains(&tag) {
        return [1.0, 0.0, 0.0, 0.0];
    }
    let largest = usize::from(tag - 252);
    let small =
        [p[0], p[1], p[2]].map(|b| (f32::from(b) / 255.0 * 2.0 - 1.0) / std::f32::consts::SQRT_2);
    let mut q = [0.0f32; 4];
    let mut rest = small.iter();
    for (k, v) in q.iter_mut().enumerate() {
        if k != largest {
            *v = rest.next().copied().unwrap_or(0.0);
        }
    }
    q[largest] = (1.0 - small.iter().map(|v| v * v).sum::<f32>())
        .max(0.0)
        .sqrt();
    q
}

/// The higher SH coefficients: per splat its palette entry's `coefficients` pixels, each
/// byte mapped by `value`.
struct Palette {
    labels: Image,
    centroids: Image,
    entries: usize,
    per_channel: usize,
}

impl Palette {
    /// Writes splat `i`'s higher coefficients into `coeffs` (coefficient-major after the DC).
    fn fill(&self, i: usize, coeffs: &mut [f32], value: &dyn Fn(u8) -> f32) {
        let at = 4 * i;
        let label =
            usize::from(self.labels.rgba[at]) | (usize::from(self.labels.rgba[at + 1]) << 8);
        let n = self.per_channel;
        if label >= self.entries {
            coeffs[3..3 + 3 * n].iter_mut().for_each(|c| *c = 0.0);
            return;
        }
        let (row, column) = (label / 64, (label % 64) * n);
        for j in 0..n {
            let (x, y) = (column + j, row);
            let px = if x < self.centroids.width && y < self.centroids.height {
                let o = 4 * (y * self.centroids.width + x);
                [
                    self.centroids.rgba[o],
                    self.centroids.rgba[o + 1],
                    self.centroids.rgba[o + 2],
                ]
            } else {
                [0, 0, 0]
            };
            for c in 0..3 {
                coeffs[(j + 1) * 3 + c] = value(px[c]);
            }
        }
    }
}

fn decode_v2(meta: &Path, m: MetaV2, store: &Store) -> Result<Splats> {
    let count = m.count;
    if count == 0 {
        return Err(Error::format(meta, "meta.json 'count'", "is 0: no splats"));
    }
    let means = means(
        meta,
        store,
        files(meta, "means", &m.means.files, 2)?,
        m.means.mins,
        m.means.maxs,
        count,
    )?;
    check_codebook(meta, "scales", &m.scales.codebook, 100.0)?;
    check_codebook(meta, "sh0", &m.sh0.codebook, 1e3)?;
    let quats_name = &files(meta, "quats", &m.quats.files, 1)?[0];
    let scales_name = &files(meta, "scales", &m.scales.files, 1)?[0];
    let sh0_name = &files(meta, "sh0", &m.sh0.files, 1)?[0];
    let quats = image(meta, store, quats_name, count, None, pixel_bound(count))?;
    let scales = image(meta, store, scales_name, count, None, pixel_bound(count))?;
    let sh0 = image(meta, store, sh0_name, count, None, pixel_bound(count))?;
    let palette = match &m.sh_n {
        Some(sh) if sh.bands > 0 => {
            let per_channel = match sh.bands {
                1 => 3,
                2 => 8,
                3 => 15,
                b => {
                    return Err(Error::format(
                        meta,
                        "meta.json 'shN.bands'",
                        format!("{b}; 1 to 3 expected"),
                    ))
                }
            };
            check_codebook(meta, "shN", &sh.codebook, 1e3)?;
            if sh.count > 1 << 16 {
                return Err(Error::format(
                    meta,
                    "meta.json 'shN.count'",
                    format!("{} palette entries; 16-bit labels address 65536", sh.count),
                ));
            }
            let names = files(meta, "shN", &sh.files, 2)?;
            let need = sh.count.div_ceil(64) * 64 * per_channel;
            let centroids = image(
                meta,
                store,
                &names[0],
                need,
                Some(64 * per_channel),
                pixel_bound(need),
            )?;
            let labels = image(meta, store, &names[1], count, None, pixel_bound(count))?;
            Some(Palette {
                labels,
                centroids,
                entries: sh.count,
                per_channel,
            })
        }
        _ => None,
    };
    let degree = palette
        .as_ref()
        .map_or(Some(0), |p| degree_of_rest(p.per_channel))
        .unwrap_or(0);
    let color = SplatColor::Sh { degree };
    let mut splats = Splats::with_capacity(count, color, SplatFormat::Sog);
    splats.source.version = Some(2);
    splats.source.antialiased = m.model.as_deref() == Some("antialiased");
    if m.model.as_deref() == Some("2dgs") {
        splats.source.notes.push("meta.json says the splats are 2D surfels (2dgs); nerfx renders them as flat 3D Gaussians".into());
    }
    splats.source.quantisation =
        format!(
        "positions 16 bits of a log-transformed range, rotations smallest-three in 8 bits, log \
         scales and colour through 256-entry codebooks, opacity 8 bits{}",
        match &palette {
            Some(p) => format!(", SH degree {degree} through a palette of {} entries", p.entries),
            None => String::new(),
        }
    );
    let mut coeffs = vec![0.0f32; color.coefficients() * 3];
    let sh_codebook = m
        .sh_n
        .as_ref()
        .map(|s| s.codebook.as_slice())
        .unwrap_or(&[]);
    let sh_value = |b: u8| sh_codebook.get(usize::from(b)).copied().unwrap_or(0.0);
    for (i, mean) in means.into_iter().enumerate() {
        let at = 4 * i;
        let s = &scales.rgba[at..at + 4];
        let log_scale = Vec3::new(
            lookup(meta, scales_name, &m.scales.codebook, s[0], i)?,
            lookup(meta, scales_name, &m.scales.codebook, s[1], i)?,
            lookup(meta, scales_name, &m.scales.codebook, s[2], i)?,
        );
        let c = &sh0.rgba[at..at + 4];
        for k in 0..3 {
            coeffs[k] = lookup(meta, sh0_name, &m.sh0.codebook, c[k], i)?;
        }
        if let Some(p) = &palette {
            p.fill(i, &mut coeffs, &sh_value);
        }
        let opacity = f32::from(c[3]) / 255.0;
        let q = quaternion(&quats.rgba[at..at + 4]);
        if !splats.push_activated(mean, log_scale.exp(), q, opacity, &coeffs) {
            splats.dropped += 1;
        }
    }
    Ok(splats)
}

fn decode_v1(meta: &Path, m: MetaV1, store: &Store) -> Result<Splats> {
    let count = m.means.shape.first().copied().unwrap_or(0);
    if count == 0 {
        return Err(Error::format(
            meta,
            "meta.json 'means.shape'",
            "gives no splats",
        ));
    }
    let means = means(
        meta,
        store,
        files(meta, "means", &m.means.files, 2)?,
        m.means.mins,
        m.means.maxs,
        count,
    )?;
    for (entry, range, want) in [("scales", &m.scales, 3), ("sh0", &m.sh0, 4)] {
        if range.mins.len() != want || range.maxs.len() != want {
            return Err(Error::format(
                meta,
                format!("meta.json '{entry}'"),
                format!("'mins' and 'maxs' need {want} values each"),
            ));
        }
    }
    check_values(meta, "scales.mins", &m.scales.mins, 100.0)?;
    check_values(meta, "scales.maxs", &m.scales.maxs, 100.0)?;
    check_values(meta, "sh0.mins", &m.sh0.mins, 1e3)?;
    check_values(meta, "sh0.maxs", &m.sh0.maxs, 1e3)?;
    let quats = image(
        meta,
        store,
        &files(meta, "quats", &m.quats.files, 1)?[0],
        count,
        None,
        pixel_bound(count),
    )?;
    let scales = image(
        meta,
        store,
        &files(meta, "scales", &m.scales.files, 1)?[0],
        count,
        None,
        pixel_bound(count),
    )?;
    let sh0 = image(
        meta,
        store,
        &files(meta, "sh0", &m.sh0.files, 1)?[0],
        count,
        None,
        pixel_bound(count),
    )?;
    let palette = match &m.sh_n {
        Some(sh) => {
            check_values(meta, "shN.mins", &[sh.mins], 1e3)?;
            check_values(meta, "shN.maxs", &[sh.maxs], 1e3)?;
            let names = files(meta, "shN", &sh.files, 2)?;
            // Version 1 gives no band count: the centroids' width tells it.
            // At most 65536 entries (16-bit labels) of 15 pixels.
            let centroids = image(meta, store, &names[0], 0, None, 1 << 20)?;
            let per_channel = match centroids.width {
                192 => 3,
                512 => 8,
                960 => 15,
                w => {
                    return Err(Error::format(
                        meta,
                        format!("image '{}'", names[0]),
                        format!("{w} pixels wide; a palette is 192, 512 or 960 (SH degree 1 to 3)"),
                    ))
                }
            };
            let labels = image(meta, store, &names[1], count, None, pixel_bound(count))?;
            let entries = centroids.width / per_channel * centroids.height;
            Some((
                Palette {
                    labels,
                    centroids,
                    entries,
                    per_channel,
                },
                sh.mins,
                sh.maxs,
            ))
        }
        None => None,
    };
    let degree = palette
        .as_ref()
        .and_then(|(p, _, _)| degree_of_rest(p.per_channel))
        .unwrap_or(0);
    let color = SplatColor::Sh { degree };
    let mut splats = Splats::with_capacity(count, color, SplatFormat::Sog);
    splats.source.version = Some(1);
    splats.source.quantisation = format!(
        "positions 16 bits of a log-transformed range, rotations smallest-three in 8 bits, log \
         scales, colour and opacity 8 bits of per-channel ranges{}",
        if degree > 0 {
            format!(", SH degree {degree} through a palette")
        } else {
            String::new()
        }
    );
    let lerp = |lo: f32, hi: f32, b: u8| lo + (hi - lo) * (f32::from(b) / 255.0);
    let mut coeffs = vec![0.0f32; color.coefficients() * 3];
    for (i, mean) in means.into_iter().enumerate() {
        let at = 4 * i;
        let s = &scales.rgba[at..at + 4];
        let log_scale = Vec3::new(
            lerp(m.scales.mins[0], m.scales.maxs[0], s[0]),
            lerp(m.scales.mins[1], m.scales.maxs[1], s[1]),
            lerp(m.scales.mins[2], m.scales.maxs[2], s[2]),
        );
        let c = &sh0.rgba[at..at + 4];
        for k in 0..3 {
            coeffs[k] = lerp(m.sh0.mins[k], m.sh0.maxs[k], c[k]);
        }
        if let Some((p, lo, hi)) = &palette {
            p.fill(i, &mut coeffs, &|b| lerp(*lo, *hi, b));
        }
        let logit = lerp(m.sh0.mins[3], m.sh0.maxs[3], c[3]);
        let opacity = 1.0 / (1.0 + (-logit).exp());
        let q = quaternion(&quats.rgba[at..at + 4]);
        if !splats.push_activated(mean, log_scale.exp(), q, opacity, &coeffs) {
            splats.dropped += 1;
        }
    }
    Ok(splats)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quaternions_and_the_log_transform_decode_as_published() {
        // Largest w (tag 252), the others at byte 127.5 ≈ 0: the identity.
        let q = quaternion(&[128, 128, 128, 252]);
        assert!((q[0] - 1.0).abs() < 1e-4 && q[1].abs() < 3e-3, "{q:?}");
        // Largest z (tag 255): w x y from r g b.
        let q = quaternion(&[255, 128, 128, 255]);
        assert!(
            (q[0] - 0.5f32.sqrt()).abs() < 1e-6 && (q[3] - 0.5f32.sqrt()).abs() < 3e-3,
            "{q:?}"
        );
        assert_eq!(quaternion(&[1, 2, 3, 7]), [1.0, 0.0, 0.0, 0.0]);
        assert!((inverse_log(2f32.ln()) - 1.0).abs() < 1e-6);
        assert!((inverse_log(-(3f32.ln())) + 2.0).abs() < 1e-6);
    }
}
