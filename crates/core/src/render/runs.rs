//! Where along a ray the marcher lays its samples: *runs*, the intervals of world distance
//! where some instance may have density, each marked with what is known inside it.
//!
//! An instance whose field gives its [spans](crate::field::Field::spans) (analytic fields)
//! contributes them exactly: the density's edges are the spans' ends, so the marcher starts
//! and ends its runs there and searches for none; a span of constant density is one piece,
//! integrated from one sample. So does one whose field gives the segments where its
//! occupancy mask is on ([`Field::mask_segments`], instant-ngp's cascades): its density is
//! a smooth interpolant cut to zero by the mask, so those ends are its only edges. Any
//! other instance contributes the segments its occupancy grid (and, beyond an unbounded
//! field's grid, its empty-space test) finds occupied, in which the marcher finds edges by
//! bisection. Over a ray the instances' intervals are cut at every span end, so that inside
//! a run each instance's density is continuous or searched, never jumping unseen.

use crate::field::{Aabb, Capabilities, Field, Occupancy, Span, Unbounded};
use crate::scene::LocalRay;

/// What the marcher knows about the density inside a run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum RunKind {
    /// Constant throughout (every instance present there gave a span of constant density):
    /// one sample, one piece.
    Constant,
    /// Continuous and without a peak of its own, the ends its only edges (every instance
    /// present gave a span): sampled just inside its ends and stepped between; no edge, thin
    /// sheet or peak to search for.
    Smooth,
    /// Continuous, the ends its only edges, as [`RunKind::Smooth`], but with bumps of its
    /// own (an instance present gave its mask's segments: a trained density, a smooth
    /// interpolant inside its mask): stepped as a searched run is, its steps judged by
    /// their jumps and curvature; no edge, thin sheet or gap to search for.
    Masked,
    /// An occupied segment of an instance that gave no spans: edges are found by bisection.
    Searched,
}

/// An interval `[start, end]` of world distance along a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Run {
    pub start: f64,
    pub(crate) end: f64,
    pub(crate) kind: RunKind,
}

/// How far inside a run's end its sample is taken, across the face the ray crosses there,
/// relative to the field-space coordinates' size: 16 times the rounding of a field-space
/// position in f32 (2^-24 relative), so the sample lands inside the span it stands for.
/// Along a ray whose direction has a component `d` on the face's axis, that is `1/|d|`
/// times as far.
const INSET: f64 = 1e-6;

/// The smallest component [`INSET`] is divided by: a ray that grazes a face more closely
/// keeps ten times [`INSET`] along it (a smaller margin across the face). Not more: the
/// sample stands for the run's end, and an opaque shell can be thinner than the inset (a
/// dense instant-ngp blob's lies within ~1e-5 of its mask's face, and at ten times the
/// inset a Preview ray's first sample was taken beyond its first bisected steps).
const MIN_CROSSING: f32 = 0.1;
/// Per-thread scratch for [`instance_runs`] and [`merge`].
#[derive(Default)]
pub(super) struct RunScratch {
    occupied: Vec<[f32; 2]>,
    spans: Vec<Span>,
    mask: Vec<[f64; 2]>,
    /// `(t, Δcovering, Δsearched, Δvarying, Δmasked, from a span)` per interval end.
    events: Vec<(f64, i32, i32, i32, i32, bool)>,
}

/// Appends one instance's intervals along its local ray to `out` (world distance): its
/// occupied segments when it has an `occupancy` grid, else its spans or its mask's
/// segments, as its field's `capabilities` declare. Returns the world distance inside a span's (or mask segment's) end at which
/// that end's sample is taken for this instance (0 when it gave neither).
pub(super) fn instance_runs(
    lr: &LocalRay,
    field: &dyn Field,
    capabilities: Capabilities,
    occupancy: Option<&Occupancy>,
    unbounded: Option<&Unbounded>,
    scratch: &mut RunScratch,
    out: &mut Vec<Run>,
) -> f64 {
    let k = lr.units_per_world as f64;
    let length = (lr.t_far - lr.t_near) * k;
    let world = |u: f64| (lr.t_near + u / k).clamp(lr.t_near, lr.t_far);
    if let Some(occupancy) = occupancy {
        scratch.occupied.clear();
        let length = length as f32;
        occupancy.segments(lr.origin, lr.dir, 0.0, length, &mut scratch.occupied);
        if let Some(u) = unbounded {
            far_segments(lr, u, field, length, &mut scratch.occupied);
        }
        out.extend(scratch.occupied.iter().map(|&[u0, u1]| Run {
            start: world(u0 as f64),
            end: world(u1 as f64),
            kind: RunKind::Searched,
        }));
        return 0.0;
    }
    let run = |start: f64, end: f64, kind: RunKind| {
        let (start, end) = (world(start), world(end));
        (start < end).then_some(Run { start, end, kind })
    };
    scratch.spans.clear();
    scratch.mask.clear();
    if capabilities.spans {
        field.spans(lr.origin, lr.dir, 0.0, length, &mut scratch.spans);
        out.extend(scratch.spans.iter().filter_map(|s| {
            let kind = if s.varies {
                RunKind::Smooth
            } else {
                RunKind::Constant
            };
            run(s.enter, s.exit, kind)
        }));
    } else if capabilities.mask_segments {
        field.mask_segments(lr.origin, lr.dir, 0.0, length, &mut scratch.mask);
        out.extend(
            scratch
                .mask
                .iter()
                .filter_map(|&[a, b]| run(a, b, RunKind::Masked)),
        );
    } else {
        return 0.0;
    }
    // Which face a run ends on is not known here: the most grazing one the ray can cross.
    let crossing = lr
        .dir
        .abs()
        .to_array()
        .into_iter()
        .filter(|&d| d > 0.0)
        .fold(1.0f32, f32::min)
        .max(MIN_CROSSING);
    INSET * (lr.origin.abs().max_element() as f64 + length + 1.0) / (k * crossing as f64)
}

/// Appends to `out` the intervals of `[0, length]` (field units along the local ray) outside
/// an unbounded field's grid cube where it may have density. The ray is walked in steps of about
/// [`Unbounded::skip`] contracted units at the finest (`skip·core·(r/core)²` field units at
/// `‖x‖∞ = r`: `r` changes by at most one unit per unit of a unit ray), each step's box
/// asked of [`Field::may_be_occupied`]. A step found empty doubles the next (so an empty shell costs a
/// few queries, not one per cell); one found occupied is retried at half the length until
/// it is the finest, and only the finest occupied steps are kept, merged when they touch.
fn far_segments(
    lr: &LocalRay,
    u: &Unbounded,
    field: &dyn Field,
    length: f32,
    out: &mut Vec<[f32; 2]>,
) {
    let outside = match u.grid_box().clip_ray(lr.origin, lr.dir, 0.0, length) {
        Some((a, b)) => [[0.0, a], [b, length]],
        None => [[0.0, length], [length, length]],
    };
    let first = out.len();
    let box_of = |t0: f32, t1: f32| {
        let (p, q) = (lr.origin + lr.dir * t0, lr.origin + lr.dir * t1);
        Aabb::new(p.min(q), p.max(q))
    };
    for [a, b] in outside {
        // A run with nothing far answers for the whole stretch at once.
        if a >= b || !field.may_be_occupied(&box_of(a, b)) {
            continue;
        }
        let (mut t, mut scale) = (a, 1.0f32);
        while t < b {
            let fine = u.skip * u.core * u.step_growth(lr.origin + lr.dir * t);
            let t1 = (t + (fine * scale).max(f32::EPSILON * t.abs())).min(b);
            if !field.may_be_occupied(&box_of(t, t1)) {
                t = t1;
                scale *= 2.0;
            } else if scale > 1.0 {
                scale = (scale * 0.5).max(1.0);
            } else {
                match out[first..].last_mut() {
                    Some(last) if last[1] >= t => last[1] = t1,
                    _ => out.push([t, t1]),
                }
                t = t1;
            }
        }
    }
}

/// Turns the instances' intervals of one ray (each instance's disjoint) into its runs:
/// sorted, not overlapping. Without spans, the occupied segments' union (overlapping ones
/// merged). With spans, the intervals are cut at every interval end and each piece covered
/// by any is a run: searched if a searched segment covers it, else masked if a mask's
/// segment does, else smooth if a varying span does, else constant; pieces of searched
/// segments that meet at an end no span has are joined, so searched fields march as they
/// would alone.
pub(super) fn merge(runs: &mut Vec<Run>, scratch: &mut RunScratch) {
    if runs.iter().all(|r| r.kind == RunKind::Searched) {
        union_in_place(runs);
        return;
    }
    if runs.iter().all(|r| r.kind != RunKind::Searched) {
        // Spans alone, and most often apart (one instance's, or instances that do not
        // overlap along this ray): sorted, they are the runs already.
        runs.sort_unstable_by(|x, y| x.start.total_cmp(&y.start));
        if runs.windows(2).all(|w| w[0].end <= w[1].start) {
            return;
        }
    }
    let events = &mut scratch.events;
    events.clear();
    for r in runs.iter() {
        let searched = i32::from(r.kind == RunKind::Searched);
        let varies = i32::from(matches!(r.kind, RunKind::Smooth | RunKind::Masked));
        let masked = i32::from(r.kind == RunKind::Masked);
        let span = r.kind != RunKind::Searched;
        events.push((r.start, 1, searched, varies, masked, span));
        events.push((r.end, -1, -searched, -varies, -masked, span));
    }
    events.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    runs.clear();
    let (mut covering, mut searched, mut varies, mut masked) = (0, 0, 0, 0);
    let mut i = 0;
    while i < events.len() {
        let x = events[i].0;
        let mut at_span_end = false;
        while i < events.len() && events[i].0 == x {
            let (_, c, s, v, m, span) = events[i];
            covering += c;
            searched += s;
            varies += v;
            masked += m;
            at_span_end |= span;
            i += 1;
        }
        let Some(&(y, ..)) = events.get(i) else {
            break;
        };
        if covering == 0 {
            continue;
        }
        let kind = if searched > 0 {
            RunKind::Searched
        } else if masked > 0 {
            RunKind::Masked
        } else if varies > 0 {
            RunKind::Smooth
        } else {
            RunKind::Constant
        };
        match runs.last_mut() {
            Some(last)
                if kind == RunKind::Searched
                    && last.kind == kind
                    && last.end == x
                    && !at_span_end =>
            {
                last.end = y;
            }
            _ => runs.push(Run {
                start: x,
                end: y,
                kind,
            }),
        }
    }
}

/// Sorts intervals and merges the overlapping ones.
fn union_in_place(runs: &mut Vec<Run>) {
    runs.sort_unstable_by(|x, y| x.start.total_cmp(&y.start));
    let mut merged = 0;
    for i in 0..runs.len() {
        let run = runs[i];
        if merged > 0 && run.start <= runs[merged - 1].end {
            runs[merged - 1].end = runs[merged - 1].end.max(run.end);
        } else if run.end >= run.start {
            runs[merged] = run;
            merged += 1;
        }
    }
    runs.truncate(merged);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(start: f64, end: f64, kind: RunKind) -> Run {
        Run { start, end, kind }
    }

    use RunKind::{Constant, Searched, Smooth};

    #[test]
    fn searched_segments_alone_are_their_union() {
        let mut runs = vec![
            run(4.0, 5.0, Searched),
            run(1.0, 2.0, Searched),
            run(1.5, 3.0, Searched),
            run(3.0, 3.5, Searched),
        ];
        merge(&mut runs, &mut RunScratch::default());
        assert_eq!(runs, [run(1.0, 3.5, Searched), run(4.0, 5.0, Searched)]);
    }

    #[test]
    fn spans_cut_every_interval_at_their_ends() {
        // A constant span inside a varying one, touching constant spans of another
        // instance, and a searched segment crossing a span end.
        let mut runs = vec![
            run(0.0, 10.0, Smooth),
            run(2.0, 3.0, Constant),
            run(12.0, 13.0, Constant),
            run(13.0, 14.0, Constant),
            run(13.5, 20.0, Searched),
            run(15.0, 16.0, Searched),
        ];
        merge(&mut runs, &mut RunScratch::default());
        assert_eq!(
            runs,
            [
                run(0.0, 2.0, Smooth),
                run(2.0, 3.0, Smooth),
                run(3.0, 10.0, Smooth),
                run(12.0, 13.0, Constant),
                run(13.0, 13.5, Constant),
                run(13.5, 14.0, Searched),
                run(14.0, 20.0, Searched),
            ]
        );
        // Two instances' constant spans overlapping: constant pieces.
        let mut runs = vec![run(0.0, 2.0, Constant), run(1.0, 3.0, Constant)];
        merge(&mut runs, &mut RunScratch::default());
        assert_eq!(
            runs,
            [
                run(0.0, 1.0, Constant),
                run(1.0, 2.0, Constant),
                run(2.0, 3.0, Constant)
            ]
        );
    }
}
