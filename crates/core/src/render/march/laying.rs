//! The step policy and the laying of a round's regular nodes along a ray's runs.

use super::{met_by, InstancePlan, Pending, Scratch, MAX_BISECTIONS};
use crate::render::runs::RunKind;
use crate::render::MarchParams;
use crate::scene::LocalRay;

/// Nodes a live ray lays per round: small, so rays that stop at a surface waste few
/// samples past it (measured: 4 and 16 cost more samples or more rounds than 8).
const CHUNK: usize = 8;

/// The step at world distance `t` on a ray whose base step there is `base` (see
/// [`base_step_at`]): the base step times the ray's current growth `scale` (or grown with
/// distance by the cone, whichever is longer), at most `max_step_factor` base steps.
fn step_at(base: f64, t: f64, scale: f64, params: &MarchParams) -> f64 {
    let grown = (params.cone as f64 * t).max(base * scale);
    grown
        .min(longest_step(base, params))
        .max(base)
        .max(f64::MIN_POSITIVE)
}

/// The longest step any rule may take where the base step is `base`.
fn longest_step(base: f64, params: &MarchParams) -> f64 {
    base * params.max_step_factor.max(1.0) as f64
}

/// The base step at world distance `t` on ray `r`, before growth and the cone: the finest
/// among the instances the ray is inside at `t` (each grown beyond an unbounded field's
/// core).
pub(super) fn base_step_at(r: usize, t: f64, plans: &[InstancePlan], s: &Scratch) -> f64 {
    let (mut here, mut anywhere) = (f64::INFINITY, f64::INFINITY);
    for met in met_by(s, r) {
        anywhere = anywhere.min(met.step);
        if t >= met.local.t_near && t <= met.local.t_far {
            here = here.min(if met.grows {
                met.step * growth(&plans[met.inst as usize], &met.local, t)
            } else {
                met.step
            });
        }
    }
    // Segments lie inside instances, so `here` is finite but for rounding at their ends.
    let base = if here.is_finite() { here } else { anywhere };
    base.max(f64::MIN_POSITIVE)
}

/// How much an instance's step grows at world distance `t` (beyond an unbounded field's
/// core; 1 elsewhere).
#[inline]
pub(super) fn growth(plan: &InstancePlan, lr: &LocalRay, t: f64) -> f64 {
    plan.unbounded
        .map_or(1.0, |u| f64::from(u.step_growth(lr.at(t))))
}

/// The shortest smooth length (world units) at world distance `t` of the instances ray `r`
/// meets ([`Field::smooth_length`](crate::field::Field::smooth_length), grown as its steps
/// grow where it is unbounded): 0 where one of them is not smooth below any length (an
/// analytic field); infinite where it meets none.
fn smooth_length_at(r: usize, t: f64, plans: &[InstancePlan], s: &Scratch) -> f64 {
    met_by(s, r)
        .iter()
        .map(|met| {
            let (plan, lr) = (&plans[met.inst as usize], &met.local);
            plan.smooth * growth(plan, lr, t) / lr.units_per_world as f64
        })
        .fold(f64::INFINITY, f64::min)
}

/// The share of a run's inset (see [`RayState::inset`](super::RayState::inset)) a masked
/// run's face is probed at first: a sixteenth, one unit of an `f32` field-space position's
/// rounding across the face.
const FACE_PROBE: f64 = 1.0 / 16.0;

/// Lays the next chunk of regular nodes for ray `r` into `s.pending`: from each run's start
/// to its end at the step policy's steps, or one node for a constant run. A run whose ends
/// are a span's is sampled just inside them (see [`RayState::inset`](super::RayState::inset)).
pub(super) fn lay_nodes(r: usize, plans: &[InstancePlan], params: &MarchParams, s: &mut Scratch) {
    if !s.rays[r].live {
        return;
    }
    let mut laid = 0;
    // The round's bisection floor is set at its first stepped node: constant runs take no
    // steps, so a round of them alone keeps the last round's (0 on the ray's first).
    let mut floor_set = false;
    while laid < CHUNK && s.rays[r].run < s.rays[r].runs.len() {
        let state = &s.rays[r];
        let run = state.runs[state.run];
        let (t, starts_run) = match state.next_t {
            Some(t) => (t, false),
            None => (run.start, true),
        };
        let exact = run.kind != RunKind::Searched;
        if run.kind == RunKind::Constant {
            let state = &mut s.rays[r];
            state.run += 1;
            s.pending.push(Pending {
                ray: r as u32,
                t: run.start,
                probe: 0.5 * (run.start + run.end),
                inward: 0.5 * (run.start + run.end),
                starts_run: true,
                exact,
                extent: run.end - run.start,
            });
            laid += 1;
            continue;
        }
        if starts_run {
            // Density may begin where a run does: its first step is a base one.
            s.rays[r].scale = 1.0;
        }
        let base = base_step_at(r, t, plans, s);
        if !floor_set {
            floor_set = true;
            s.rays[r].finest = base * 0.5f64.powi(params.refine_depth.min(MAX_BISECTIONS) as i32);
            s.rays[r].smooth = smooth_length_at(r, t, plans, s);
        }
        let state = &mut s.rays[r];
        let step = if exact && run.kind != RunKind::Masked {
            // An exact run holds no edge: its steps are the error rule's, growing at most
            // twofold from node to node, from a base step where the run starts. A masked
            // run's density has bumps of its own, which the round behind cannot foresee:
            // it is stepped as a searched run is.
            let reach = if starts_run {
                base
            } else {
                2.0 * state.last_step
            };
            let step = reach
                .min(state.allowed)
                .min(longest_step(base, params))
                .max(state.finest);
            state.last_step = step;
            step.max(f64::MIN_POSITIVE)
        } else {
            let step = step_at(base, t, state.scale, params);
            if state.growing {
                state.scale = (2.0 * state.scale).min(params.max_step_factor.max(1.0) as f64);
            }
            step
        };
        let next = (t < run.end).then(|| (t + step).min(run.end));
        let at_end = match next {
            Some(n) if n > t => {
                state.next_t = Some(n);
                false
            }
            _ => {
                state.run += 1;
                state.next_t = None;
                true
            }
        };
        let inset = if exact {
            state.inset.min(0.25 * (run.end - run.start))
        } else {
            0.0
        };
        // A masked run's face is probed first within a unit of rounding of it, where its
        // density is (an opaque shell can be thinner than the inset), and only where that
        // rounds out of the mask the full inset inside.
        let near = if run.kind == RunKind::Masked {
            inset * FACE_PROBE
        } else {
            inset
        };
        let (probe, inward) = if starts_run {
            (t + near, t + inset)
        } else if at_end {
            (t - near, t - inset)
        } else {
            (t, t)
        };
        s.pending.push(Pending {
            ray: r as u32,
            t,
            probe,
            inward,
            starts_run,
            exact,
            extent: 0.0,
        });
        laid += 1;
    }
}
