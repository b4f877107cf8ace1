//! Deep output: a ray's pieces and fragments as deep samples `[Z, ZBack]`.
//!
//! Each piece the integrator composites (a marched step, a closed-form piece, a proposal or
//! instant-ngp sample, a splat fragment at its depth) with weight `w` and premultiplied
//! colour contribution `C`, entered with transmittance `T`, becomes a sample of opacity
//! `α = w/T` and premultiplied colour `C/T`: compositing the samples front to back with *over*
//! gives back `Σ w` and `Σ C`, the flat pixel.
//!
//! Adjacent samples are merged while the merge changes what a point put between them would
//! see by less than the preset's error target ([`merge`]); a pixel keeps at most
//! [`DeepParams::max_samples`] samples whatever the content.
//!
//! Worked example: two pieces of α = ½ each, white: samples `(α ½, C ½)` and, entered at
//! `T = ½`, `(α ½, C ½)`; over: `C = ½ + ½·½ = ¾`, `α = 1 − ½·½ = ¾`.

use glam::DVec3;
use serde::{Deserialize, Serialize};

use super::integrator::srgb_composite_to_linear;
use crate::error::{Error, Result};
use crate::image::{DeepImage, DeepSample, Planes, Window};

/// Most samples a merged group may hold: the merge test looks at every boundary inside the
/// group, so this bounds its cost per piece.
const MAX_GROUP: usize = 64;

/// Most samples a pixel may be asked to keep (`--deep-samples`).
pub const MAX_DEEP_SAMPLES: u32 = 4096;

/// What a deep render keeps per pixel.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DeepParams {
    /// Most samples per pixel (1 to [`MAX_DEEP_SAMPLES`]).
    pub max_samples: u32,
    /// Adjacent samples merge while a point between them would see its transmittance and the
    /// colour in front of it change by less than this (the preset's error target).
    pub error_target: f32,
}

impl DeepParams {
    /// Refuses a cap outside 1 to [`MAX_DEEP_SAMPLES`] or an error target that is not a
    /// positive number.
    pub fn validate(&self) -> Result<()> {
        if !(1..=MAX_DEEP_SAMPLES).contains(&self.max_samples) {
            return Err(Error::invalid(
                "deep samples",
                format!("{}; expected 1 to {MAX_DEEP_SAMPLES}", self.max_samples),
            ));
        }
        if !(self.error_target.is_finite() && self.error_target > 0.0) {
            return Err(Error::invalid(
                "deep error target",
                format!("{}; expected a positive number", self.error_target),
            ));
        }
        Ok(())
    }
}

/// One composited piece of a ray: `[t0, t1]` (ray distance, world units; equal for a
/// fragment), its weight `w = T·α` and premultiplied colour contribution.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct RawPiece {
    pub t0: f64,
    pub t1: f64,
    pub(crate) weight: f64,
    pub rgb: DVec3,
}

/// A sample while it is worked on: in f64, depths in camera Z.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Sample {
    front: f64,
    back: f64,
    rgb: [f64; 3],
    alpha: f64,
}

/// A tile's deep pixels, in the order of its pixels: pixel `i` holds
/// `samples[offsets[i]..offsets[i + 1]]`.
#[derive(Clone, Debug, Default)]
pub(super) struct DeepTile {
    pub(crate) offsets: Vec<u32>,
    pub(crate) samples: Vec<DeepSample>,
}

impl DeepTile {
    pub fn clear(&mut self) {
        self.offsets.clear();
        self.offsets.push(0);
        self.samples.clear();
    }

    /// Closes the pixel whose samples were just pushed.
    pub(crate) fn end_pixel(&mut self) {
        self.offsets.push(self.samples.len() as u32);
    }
}

/// Per-thread scratch of [`finish_pixel`].
#[derive(Default)]
pub(super) struct DeepScratch {
    samples: Vec<Sample>,
    merged: Vec<Sample>,
    bounds: Vec<(f64, f64, [f64; 3])>,
}

/// The deep samples of one pixel from its composited `pieces` (front to back), pushed onto
/// `out`: depths as camera Z (`z_per_t` per unit ray distance), merged ([`merge`]), and, where
/// the flat pixel was composited in sRGB-encoded space and converted (`decode`), each sample
/// converted the same way and the colours then scaled so that they flatten to `pixel_rgb`,
/// the flat pixel's colour.
pub(super) fn finish_pixel(
    pieces: &[RawPiece],
    z_per_t: f64,
    pixel_rgb: [f32; 3],
    decode: bool,
    params: &DeepParams,
    s: &mut DeepScratch,
    out: &mut DeepTile,
) {
    s.samples.clear();
    let mut transmittance = 1.0f64;
    for p in pieces {
        if p.weight.is_nan() || p.weight <= 0.0 || transmittance <= 0.0 {
            continue;
        }
        let alpha = (p.weight / transmittance).min(1.0);
        let (a, b) = (p.t0 * z_per_t, p.t1 * z_per_t);
        s.samples.push(Sample {
            front: a.min(b),
            back: a.max(b),
            rgb: (p.rgb / transmittance).to_array(),
            alpha,
        });
        transmittance = (transmittance - p.weight).max(0.0);
    }
    merge(&s.samples, params, &mut s.bounds, &mut s.merged);
    if decode {
        for m in &mut s.merged {
            let rgb = m.rgb.map(|c| c as f32);
            m.rgb = srgb_composite_to_linear(rgb, m.alpha as f32).map(f64::from);
        }
    }
    conform_samples(&mut s.merged, pixel_rgb);
    out.samples.extend(s.merged.iter().map(|m| DeepSample {
        front: m.front as f32,
        back: m.back as f32,
        rgb: m.rgb.map(|c| c as f32),
        alpha: m.alpha as f32,
    }));
    out.end_pixel();
}

/// Scales each colour channel of `samples` so that they flatten to `rgb` (where they flatten
/// to anything but zero): a conversion of the flat pixel that is not linear in the samples'
/// colours (sRGB decoding, a display encoding) leaves the flattened deep pixel equal to it.
fn conform_samples(samples: &mut [Sample], rgb: [f32; 3]) {
    let mut flat = [0.0f64; 3];
    let mut transmittance = 1.0;
    for s in samples.iter() {
        for (f, c) in flat.iter_mut().zip(s.rgb) {
            *f += transmittance * c;
        }
        transmittance *= 1.0 - s.alpha;
    }
    for (k, f) in flat.iter().enumerate() {
        let want = f64::from(rgb[k]);
        if f.abs() > 1e-30 && (want - f).abs() > 0.0 {
            let scale = want / f;
            if scale.is_finite() {
                for s in samples.iter_mut() {
                    s.rgb[k] *= scale;
                }
            }
        }
    }
}

/// Scales the colours of every pixel of `deep` so that each flattens to the colour of
/// `planes` there (see `conform_samples`), after a colour-space conversion applied to both.
pub fn conform_to(deep: &mut DeepImage, planes: &Planes) {
    let Some([r, g, b]) = &planes.rgb else {
        return;
    };
    for p in 0..deep.offsets.len().saturating_sub(1) {
        let pixel = deep.pixel_mut(p);
        let mut samples: Vec<Sample> = pixel
            .iter()
            .map(|d| Sample {
                front: d.front.into(),
                back: d.back.into(),
                rgb: d.rgb.map(f64::from),
                alpha: d.alpha.into(),
            })
            .collect();
        conform_samples(&mut samples, [r.data[p], g.data[p], b.data[p]]);
        for (d, s) in pixel.iter_mut().zip(&samples) {
            d.rgb = s.rgb.map(|c| c as f32);
        }
    }
}

/// What a point at depth `z` inside `m` sees in front of it, as OpenEXR splits a volume
/// sample (its optical depth spread evenly over `[front, back]`): the transmittance and the
/// premultiplied colour in front of `z`.
#[inline]
fn split(m: &Sample, z: f64) -> (f64, [f64; 3]) {
    let length = m.back - m.front;
    if length.is_nan() || length <= 0.0 {
        return (1.0 - m.alpha, m.rgb);
    }
    let f = ((z - m.front) / length).clamp(0.0, 1.0);
    if f == 0.0 {
        return (1.0, [0.0; 3]);
    }
    let t = if m.alpha >= 1.0 {
        0.0
    } else {
        (f * (-m.alpha).ln_1p()).exp()
    };
    let share = if m.alpha > 0.0 {
        (1.0 - t) / m.alpha
    } else {
        f
    };
    (t, m.rgb.map(|c| c * share))
}

/// Merges adjacent `samples` (sorted, not overlapping) into `out`, front to back: a group
/// grows while, for every boundary between its members, a point there would see its
/// transmittance and the colour in front of it (each times the transmittance in front of the
/// group) change by less than the error target once the group is one sample; at most
/// [`MAX_GROUP`] members a group. Past [`DeepParams::max_samples`] samples, the pixel is cut
/// instead into that many groups holding equal shares of its opacity.
///
/// A merged sample composites its members: `α = 1 − Π(1 − αᵢ)`, colour `Σ Tᵢ cᵢ` (`Tᵢ` the
/// transmittance inside the group in front of member `i`), over `[first front, last back]`.
fn merge(
    samples: &[Sample],
    params: &DeepParams,
    bounds: &mut Vec<(f64, f64, [f64; 3])>,
    out: &mut Vec<Sample>,
) {
    out.clear();
    let target = f64::from(params.error_target);
    let mut in_front = 1.0f64;
    let mut i = 0;
    while i < samples.len() {
        let mut group = samples[i];
        let mut members = 1;
        bounds.clear();
        let mut j = i + 1;
        while j < samples.len() && members < MAX_GROUP {
            let next = samples[j];
            let candidate = over(&group, &next);
            let inside = (1.0 - group.alpha, group.rgb);
            let fits = |&(z, t, c): &(f64, f64, [f64; 3])| {
                let (t_lin, c_lin) = split(&candidate, z);
                let worst = (0..3).fold((t_lin - t).abs(), |w, k| w.max((c_lin[k] - c[k]).abs()));
                in_front * worst < target
            };
            let new = [
                (group.back, inside.0, inside.1),
                (next.front, inside.0, inside.1),
            ];
            // Behind an opaque enough front no boundary can see more than the bound: the
            // change in transmittance is at most 1, in colour at most the group's colour.
            let brightest = candidate.rgb.iter().fold(1.0f64, |m, c| m.max(c.abs()));
            let unseen = in_front * brightest < target;
            if !(unseen || (bounds.iter().all(fits) && new.iter().all(fits))) {
                break;
            }
            bounds.extend(new);
            group = candidate;
            members += 1;
            j += 1;
        }
        in_front *= 1.0 - group.alpha;
        out.push(group);
        i = j;
    }
    let cap = params.max_samples.max(1) as usize;
    if out.len() > cap {
        cut_into_equal_opacity(samples, cap, out);
    }
}

/// `a` with `b` (just behind it) composited into one sample.
#[inline]
fn over(a: &Sample, b: &Sample) -> Sample {
    let t = 1.0 - a.alpha;
    Sample {
        front: a.front,
        back: a.back.max(b.back),
        rgb: [0, 1, 2].map(|k| a.rgb[k] + t * b.rgb[k]),
        alpha: 1.0 - t * (1.0 - b.alpha),
    }
}

/// `samples` merged into at most `cap` groups, each holding an equal share of the pixel's
/// opacity (`1 − T` in front of a sample decides its group).
fn cut_into_equal_opacity(samples: &[Sample], cap: usize, out: &mut Vec<Sample>) {
    out.clear();
    let total = 1.0 - samples.iter().fold(1.0, |t, s| t * (1.0 - s.alpha));
    let mut transmittance = 1.0;
    let mut current: Option<(usize, Sample)> = None;
    for s in samples {
        let opacity = 1.0 - transmittance;
        let group = if total > 0.0 {
            ((opacity / total * cap as f64) as usize).min(cap - 1)
        } else {
            0
        };
        current = match current {
            Some((g, m)) if g == group => Some((g, over(&m, s))),
            Some((_, m)) => {
                out.push(m);
                Some((group, *s))
            }
            None => Some((group, *s)),
        };
        transmittance *= 1.0 - s.alpha;
    }
    out.extend(current.map(|(_, m)| m));
}

/// The deep pixel that a motion-blurred frame's shutter samples average to: pushed onto
/// `out`, merged with `params`. Each sample's list is cut at every depth where any list's
/// samples start or end (a volume sample's optical depth spread evenly over it, as OpenEXR
/// splits one); in each slot (a depth, or the stretch to the next) the absolute opacity and
/// colour the lists add there are averaged, and the averaged increments become samples
/// entered with the averaged transmittance. So the result flattens exactly to the average
/// of the lists' flattenings (the flat motion-blurred pixel), and a point at any slot
/// boundary sees the average of what it sees in each shutter sample.
pub(crate) fn average_pixels(
    lists: &[&[DeepSample]],
    params: &DeepParams,
    out: &mut Vec<DeepSample>,
) {
    let mut bounds: Vec<f64> = lists
        .iter()
        .flat_map(|l| {
            l.iter()
                .flat_map(|s| [f64::from(s.front), f64::from(s.back)])
        })
        .collect();
    bounds.sort_by(f64::total_cmp);
    bounds.dedup();
    if bounds.is_empty() || lists.is_empty() {
        return;
    }
    // Slot 2k: the point bounds[k]; slot 2k + 1: the stretch (bounds[k], bounds[k + 1]).
    let slots = 2 * bounds.len();
    let mut added = vec![(0.0f64, [0.0f64; 3]); slots];
    let at = |z: f32| bounds.partition_point(|&b| b < f64::from(z));
    for list in lists {
        let mut transmittance = 1.0f64;
        for s in list.iter() {
            let alpha = f64::from(s.alpha).clamp(0.0, 1.0);
            let rgb = s.rgb.map(f64::from);
            if s.front >= s.back {
                let slot = &mut added[2 * at(s.front)];
                slot.0 += transmittance * alpha;
                for (added, c) in slot.1.iter_mut().zip(rgb) {
                    *added += transmittance * c;
                }
                transmittance *= 1.0 - alpha;
                continue;
            }
            let (k0, k1) = (at(s.front), at(s.back));
            let length = f64::from(s.back) - f64::from(s.front);
            let whole = Sample {
                front: s.front.into(),
                back: s.back.into(),
                rgb,
                alpha,
            };
            let mut before = (1.0, [0.0; 3]);
            for k in k0..k1 {
                let z = if k + 1 == k1 {
                    f64::from(s.back)
                } else {
                    bounds[k + 1]
                };
                let after = if k + 1 == k1 {
                    (1.0 - alpha, rgb)
                } else {
                    split(&whole, z.min(f64::from(s.front) + length))
                };
                let slot = &mut added[2 * k + 1];
                slot.0 += transmittance * (before.0 - after.0);
                for c in 0..3 {
                    slot.1[c] += transmittance * (after.1[c] - before.1[c]);
                }
                before = after;
            }
            transmittance *= 1.0 - alpha;
        }
    }
    let n = lists.len() as f64;
    let mut samples = Vec::new();
    let mut transmittance = 1.0f64;
    for (slot, (a, c)) in added.iter().enumerate() {
        let (a, c) = (a / n, c.map(|v| v / n));
        if a <= 0.0 && c.iter().all(|&v| v == 0.0) {
            continue;
        }
        let k = slot / 2;
        let (front, back) = if slot % 2 == 0 {
            (bounds[k], bounds[k])
        } else {
            (bounds[k], bounds.get(k + 1).copied().unwrap_or(bounds[k]))
        };
        let t = transmittance.max(1e-300);
        samples.push(Sample {
            front,
            back,
            rgb: c.map(|v| v / t),
            alpha: (a / t).clamp(0.0, 1.0),
        });
        transmittance = (transmittance - a).max(0.0);
    }
    let mut merged = Vec::new();
    merge(&samples, params, &mut Vec::new(), &mut merged);
    out.extend(merged.iter().map(|m| DeepSample {
        front: m.front as f32,
        back: m.back as f32,
        rgb: m.rgb.map(|c| c as f32),
        alpha: m.alpha as f32,
    }));
}

/// The deep image of `window` from its tiles' pixels.
pub(super) fn assemble(window: Window, tiles: Vec<(Window, DeepTile)>) -> DeepImage {
    let (w, h) = (window.width() as usize, window.height() as usize);
    let mut counts = vec![0u64; w * h];
    for (tile, deep) in &tiles {
        let tw = tile.width() as usize;
        for (i, pair) in deep.offsets.windows(2).enumerate() {
            let (x, y) = (
                (tile.x0 - window.x0) as usize + i % tw,
                (tile.y0 - window.y0) as usize + i / tw,
            );
            counts[y * w + x] = u64::from(pair[1] - pair[0]);
        }
    }
    let mut offsets = Vec::with_capacity(w * h + 1);
    offsets.push(0u64);
    for c in &counts {
        offsets.push(offsets[offsets.len() - 1] + c);
    }
    let total = offsets[w * h] as usize;
    let mut samples = vec![DeepSample::default(); total];
    for (tile, deep) in &tiles {
        let tw = tile.width() as usize;
        for (i, pair) in deep.offsets.windows(2).enumerate() {
            let (x, y) = (
                (tile.x0 - window.x0) as usize + i % tw,
                (tile.y0 - window.y0) as usize + i / tw,
            );
            let start = offsets[y * w + x] as usize;
            let from = &deep.samples[pair[0] as usize..pair[1] as usize];
            samples[start..start + from.len()].copy_from_slice(from);
        }
    }
    DeepImage {
        width: window.width(),
        height: window.height(),
        offsets,
        samples,
    }
}

/// The deep image that `frames` (one per shutter sample, of one size) average to
/// (`average_pixels` per pixel).
pub fn average_images(frames: &[DeepImage], params: &DeepParams) -> Result<DeepImage> {
    let Some(first) = frames.first() else {
        return Err(Error::invalid("deep motion blur", "no shutter sample"));
    };
    if frames
        .iter()
        .any(|f| (f.width, f.height) != (first.width, first.height))
    {
        return Err(Error::invalid(
            "deep motion blur",
            "shutter samples of different sizes",
        ));
    }
    let pixels = first.width as usize * first.height as usize;
    let mut offsets = Vec::with_capacity(pixels + 1);
    offsets.push(0u64);
    let mut samples = Vec::new();
    let mut lists: Vec<&[DeepSample]> = Vec::with_capacity(frames.len());
    for p in 0..pixels {
        lists.clear();
        lists.extend(
            frames
                .iter()
                .map(|f| &f.samples[f.offsets[p] as usize..f.offsets[p + 1] as usize]),
        );
        average_pixels(&lists, params, &mut samples);
        offsets.push(samples.len() as u64);
    }
    Ok(DeepImage {
        width: first.width,
        height: first.height,
        offsets,
        samples,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flatten(samples: &[Sample]) -> ([f64; 3], f64) {
        let (mut c, mut t) = ([0.0; 3], 1.0);
        for s in samples {
            for (c, v) in c.iter_mut().zip(s.rgb) {
                *c += t * v;
            }
            t *= 1.0 - s.alpha;
        }
        (c, 1.0 - t)
    }

    /// A uniform fog cut in 500 pieces merges into one sample (the split of one sample is
    /// exact for constant density and colour), and flattening is unchanged.
    #[test]
    fn uniform_fog_merges_to_one_sample() {
        let params = DeepParams {
            max_samples: 32,
            error_target: 1e-3,
        };
        let alpha = 1.0 - (-0.01f64).exp();
        let samples: Vec<Sample> = (0..500)
            .map(|i| Sample {
                front: i as f64 * 0.1,
                back: (i + 1) as f64 * 0.1,
                rgb: [0.5 * alpha; 3],
                alpha,
            })
            .collect();
        let mut out = Vec::new();
        merge(&samples, &params, &mut Vec::new(), &mut out);
        assert!(out.len() <= 500 / MAX_GROUP + 1, "{}", out.len());
        let (a, b) = (flatten(&samples), flatten(&out));
        assert!((a.1 - b.1).abs() < 1e-12 && (a.0[0] - b.0[0]).abs() < 1e-12);
    }

    /// Two opaque-ish surfaces far apart stay apart; a cap of one merges them.
    #[test]
    fn surfaces_stay_apart_unless_capped() {
        let s = |z: f64, c: f64| Sample {
            front: z,
            back: z,
            rgb: [c * 0.6; 3],
            alpha: 0.6,
        };
        let samples = [s(1.0, 1.0), s(5.0, 0.2)];
        let mut out = Vec::new();
        let mut params = DeepParams {
            max_samples: 8,
            error_target: 1e-3,
        };
        merge(&samples, &params, &mut Vec::new(), &mut out);
        assert_eq!(out.len(), 2);
        params.max_samples = 1;
        merge(&samples, &params, &mut Vec::new(), &mut out);
        assert_eq!(out.len(), 1);
        let (a, b) = (flatten(&samples), flatten(&out));
        assert!((a.1 - b.1).abs() < 1e-12 && (a.0[0] - b.0[0]).abs() < 1e-12);
    }

    /// Averaging shutter samples flattens to the average of their flattenings.
    #[test]
    fn averaged_lists_flatten_to_the_average() {
        let d = |front: f32, back: f32, c: f32, alpha: f32| DeepSample {
            front,
            back,
            rgb: [c * alpha, 0.5 * c * alpha, 0.0],
            alpha,
        };
        let a = [d(1.0, 2.0, 1.0, 0.5), d(3.0, 3.0, 0.2, 0.9)];
        let b = [d(1.5, 4.0, 0.4, 0.7)];
        let params = DeepParams {
            max_samples: 64,
            error_target: 1e-6,
        };
        let mut out = Vec::new();
        average_pixels(&[&a, &b], &params, &mut out);
        let as_samples = |l: &[DeepSample]| -> Vec<Sample> {
            l.iter()
                .map(|s| Sample {
                    front: s.front.into(),
                    back: s.back.into(),
                    rgb: s.rgb.map(f64::from),
                    alpha: s.alpha.into(),
                })
                .collect()
        };
        let (fa, fb, fo) = (
            flatten(&as_samples(&a)),
            flatten(&as_samples(&b)),
            flatten(&as_samples(&out)),
        );
        assert!((fo.1 - 0.5 * (fa.1 + fb.1)).abs() < 1e-6, "{fo:?}");
        for k in 0..2 {
            assert!((fo.0[k] - 0.5 * (fa.0[k] + fb.0[k])).abs() < 1e-6, "{fo:?}");
        }
        assert!(out.windows(2).all(|p| p[0].back <= p[1].front));
    }
}
