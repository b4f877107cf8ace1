//! Property tests of `Occupancy::segments` on seeded random analytic scenes: conservative
//! (every dense sample of a ray lies in a returned segment), tight (a sphere's chord plus at
//! most a cell diagonal each side), and equal to a brute-force walk of the finest grid.

use glam::{DVec3, Vec3};
use nerfx_core::field::{Aabb, Analytic, Field, Occupancy, Primitive, ShColor, Shape};

use crate::common::rng;
use rng::SplitMix64 as Rng;

fn random_primitive(rng: &mut Rng) -> Primitive {
    let center = rng.vec(-1.0, 1.0);
    let shape = match rng.below(3) {
        0 => Shape::Sphere {
            center,
            radius: rng.range(0.05, 0.6),
        },
        1 => {
            let half = Vec3::new(
                rng.range(0.02, 0.5),
                rng.range(0.02, 0.5),
                rng.range(0.02, 0.5),
            );
            Shape::Box {
                min: center - half,
                max: center + half,
            }
        }
        _ => Shape::Gaussian {
            center,
            sigma: rng.range(0.03, 0.25),
            cutoff: rng.range(1.5, 4.0),
        },
    };
    Primitive {
        shape,
        density: rng.range(0.5, 10.0),
        color: ShColor::constant(Vec3::ONE),
    }
}

fn random_scene(rng: &mut Rng) -> Analytic {
    let n = 1 + rng.below(5) as usize;
    let field = Analytic {
        primitives: (0..n).map(|_| random_primitive(rng)).collect(),
    };
    field.validate().unwrap();
    field
}

/// A ray that is one of the awkward kinds: general, axis-parallel, grazing (one direction
/// component tiny), starting inside the bounds, starting on a cell face, or aimed at a
/// primitive.
fn random_ray(rng: &mut Rng, field: &Analytic, occ: &Occupancy) -> (Vec3, Vec3) {
    let b = occ.bounds();
    let inside = |rng: &mut Rng| b.min + Vec3::new(rng.unit(), rng.unit(), rng.unit()) * b.size();
    match rng.below(6) {
        0 => (rng.vec(-3.0, 3.0), rng.dir()),
        1 => {
            let mut d = Vec3::ZERO;
            d[rng.below(3) as usize] = if rng.unit() < 0.5 { 1.0 } else { -1.0 };
            let mut o = inside(rng);
            let a = rng.below(3) as usize;
            if d[a] != 0.0 {
                o[a] = b.min[a] - 1.0;
                d[a] = 1.0;
            }
            (o, d)
        }
        2 => {
            let mut d = rng.dir();
            let a = rng.below(3) as usize;
            d[a] = [1e-3, -1e-5, 1e-7, -1e-9][rng.below(4) as usize];
            (inside(rng), d.normalize())
        }
        3 => (inside(rng), rng.dir()),
        4 => {
            // Origin exactly on a plane of the finest grid, the way the grid computes it.
            let n = occ.resolution();
            let a = rng.below(3) as usize;
            let k = rng.below(u64::from(n) + 1);
            let mut o = inside(rng);
            o[a] = b.min[a] + k as f32 * (b.size()[a] / n as f32);
            let mut d = rng.dir();
            if rng.unit() < 0.5 {
                // Lying in the face plane.
                d[a] = 0.0;
                d = d.normalize();
            }
            (o, d)
        }
        _ => {
            let i = rng.below(field.primitives.len() as u64) as usize;
            let target = field.primitives[i].shape.bounds().center() + rng.vec(-0.1, 0.1);
            let o = rng.dir() * 3.0;
            (o, (target - o).normalize())
        }
    }
}

fn covered(segments: &[[f32; 2]], t: f32) -> bool {
    segments.iter().any(|s| s[0] <= t && t <= s[1])
}

fn check_well_formed(segments: &[[f32; 2]], t0: f32, t1: f32) {
    for s in segments {
        assert!(
            t0 <= s[0] && s[0] <= s[1] && s[1] <= t1,
            "{segments:?} in [{t0}, {t1}]"
        );
    }
    for w in segments.windows(2) {
        assert!(w[0][1] < w[1][0], "not sorted/merged: {segments:?}");
    }
}

/// Samples the ray densely over where the field may have density, plus a geometric series of
/// offsets just outside each segment end; every sample with density must be covered.
fn assert_conservative(
    field: &Analytic,
    segments: &[[f32; 2]],
    o: Vec3,
    d: Vec3,
    t0: f32,
    t1: f32,
) {
    let Some((lo, hi)) = field.bounds().clip_ray(o, d, t0, t1) else {
        return;
    };
    let n = 20_000;
    let mut ts: Vec<f32> = (0..n)
        .map(|i| lo + (hi - lo) * (i as f32 + 0.5) / n as f32)
        .collect();
    ts.push(lo);
    ts.push(hi);
    for s in segments {
        for e in 0..40 {
            let delta = 1e-9 * 1.6f32.powi(e);
            ts.push(s[0] - delta);
            ts.push(s[1] + delta);
        }
    }
    ts.retain(|t| (t0..=t1).contains(t));
    let pts: Vec<Vec3> = ts.iter().map(|&t| o + t * d).collect();
    let mut sigma = vec![0.0; pts.len()];
    field.density(&pts, &mut sigma);
    for (&t, &s) in ts.iter().zip(&sigma) {
        assert!(
            s == 0.0 || covered(segments, t),
            "density {s} at t = {t} (p = {}) outside {segments:?}; ray {o} {d}",
            o + t * d
        );
    }
}

/// The slow reference: every crossing of a finest-grid plane (in f64), the occupancy of each
/// piece read at its midpoint, touching occupied pieces merged.
fn brute_force(occ: &Occupancy, o: Vec3, d: Vec3, t0: f32, t1: f32) -> Vec<[f64; 2]> {
    let b = occ.bounds();
    let n = occ.resolution();
    let (od, dd) = (o.as_dvec3(), d.as_dvec3());
    let (mut ta, mut tb) = (f64::from(t0), f64::from(t1));
    for a in 0..3 {
        let (lo, hi) = (f64::from(b.min[a]), f64::from(b.max[a]));
        if dd[a] == 0.0 {
            if od[a] < lo || od[a] > hi {
                return Vec::new();
            }
        } else {
            let (x, y) = ((lo - od[a]) / dd[a], (hi - od[a]) / dd[a]);
            ta = ta.max(x.min(y));
            tb = tb.min(x.max(y));
        }
    }
    if ta > tb {
        return Vec::new();
    }
    let mut cuts = vec![ta, tb];
    for a in 0..3 {
        if dd[a] != 0.0 {
            let cell = b.size()[a] / n as f32;
            for k in 0..=n {
                let plane = f64::from(b.min[a] + k as f32 * cell);
                let t = (plane - od[a]) / dd[a];
                if t > ta && t < tb {
                    cuts.push(t);
                }
            }
        }
    }
    cuts.sort_by(f64::total_cmp);
    let mut out: Vec<[f64; 2]> = Vec::new();
    for w in cuts.windows(2) {
        let mid = 0.5 * (w[0] + w[1]);
        let p: DVec3 = od + mid * dd;
        if occ.is_occupied_point(p.as_vec3()) {
            match out.last_mut() {
                Some(last) if last[1] >= w[0] => last[1] = w[1],
                _ => out.push([w[0], w[1]]),
            }
        }
    }
    out
}

/// The segments of one ray, checked: well formed, conservative, and equal to the
/// brute-force walk (same pieces, ends equal up to the padding and the rounding of a plane
/// crossing, which grows as 1/|dᵢ|).
fn check_ray(
    what: &str,
    field: &Analytic,
    occ: &Occupancy,
    o: Vec3,
    d: Vec3,
    t0: f32,
    t1: f32,
) -> Vec<[f32; 2]> {
    let mut seg = Vec::new();
    occ.segments(o, d, t0, t1, &mut seg);
    check_well_formed(&seg, t0, t1);
    assert_conservative(field, &seg, o, d, t0, t1);
    let reference = brute_force(occ, o, d, t0, t1);
    let res = occ.resolution();
    let cell = occ.bounds().size() / res as f32;
    let min_d = d
        .abs()
        .to_array()
        .into_iter()
        .filter(|&x| x > 0.0)
        .fold(1.0, f32::min);
    let tol = 3e-3 * f64::from(cell.min_element())
        + 1e-6 * f64::from(1.0 + o.abs().max_element()) / f64::from(min_d);
    let ctx = format!("{what} res {res} ray {o} {d} [{t0}, {t1}]");
    assert_eq!(
        seg.len(),
        reference.len(),
        "{ctx}: {seg:?} vs {reference:?}"
    );
    for (s, r) in seg.iter().zip(&reference) {
        assert!(
            (f64::from(s[0]) - r[0]).abs() <= tol && (f64::from(s[1]) - r[1]).abs() <= tol,
            "{ctx}: {seg:?} vs {reference:?}"
        );
    }
    seg
}

#[test]
fn random_scenes_are_conservative_and_match_brute_force() {
    let mut rng = Rng::new(0x5eed_0cc0_0000_0001);
    let mut rays = 0;
    let mut hits = 0;
    for scene in 0..30 {
        let field = random_scene(&mut rng);
        for &res in &[16u32, 37, 64] {
            let occ = Occupancy::build(&field, res);
            for _ in 0..20 {
                let (o, d) = random_ray(&mut rng, &field, &occ);
                let (t0, t1) = if rng.unit() < 0.7 {
                    (0.0, 10.0)
                } else {
                    (rng.range(0.0, 2.0), rng.range(2.0, 5.0))
                };
                let seg = check_ray(&format!("scene {scene}"), &field, &occ, o, d, t0, t1);
                rays += 1;
                hits += usize::from(!seg.is_empty());
            }
        }
    }
    // The generator must exercise both outcomes.
    assert!(hits > rays / 4 && hits < rays, "{hits} of {rays}");
}

fn sphere_field(center: Vec3, radius: f32) -> Analytic {
    Analytic {
        primitives: vec![Primitive {
            shape: Shape::Sphere { center, radius },
            density: 3.0,
            color: ShColor::constant(Vec3::ONE),
        }],
    }
}

#[test]
fn rays_that_miss_get_no_segments() {
    let field = Analytic {
        primitives: vec![
            sphere_field(Vec3::new(-1.0, 0.0, 0.0), 0.5).primitives[0],
            sphere_field(Vec3::new(1.0, 0.0, 0.0), 0.5).primitives[0],
        ],
    };
    let occ = Occupancy::build(&field, 64);
    let cell = occ.bounds().size().max_element() / 64.0;
    let mut seg = Vec::new();
    // Far outside the bounds, axis-parallel.
    occ.segments(Vec3::splat(10.0), Vec3::X, 0.0, 100.0, &mut seg);
    // Through the bounds, between the two spheres (x = 0 is 0.5 from both surfaces).
    occ.segments(Vec3::new(0.0, -5.0, 0.0), Vec3::Y, 0.0, 100.0, &mut seg);
    occ.segments(Vec3::new(0.0, 0.0, -5.0), Vec3::Z, 0.0, 100.0, &mut seg);
    // Above both spheres, along x, by more than two cells.
    occ.segments(
        Vec3::new(-5.0, 0.5 + 3.0 * cell, 0.0),
        Vec3::X,
        0.0,
        100.0,
        &mut seg,
    );
    // Pointing away from the field.
    occ.segments(Vec3::new(-3.0, 0.0, 0.0), -Vec3::X, 0.0, 100.0, &mut seg);
    // Hitting it, but only beyond t1.
    occ.segments(Vec3::new(-5.0, 0.0, 0.0), Vec3::X, 0.0, 3.0, &mut seg);
    assert!(seg.is_empty(), "{seg:?}");
}

/// `t` range where the ray is within `r` of `c` (f64, closed form), if any.
fn chord(o: Vec3, d: Vec3, c: Vec3, r: f64) -> Option<(f64, f64, f64)> {
    let (o, d, c) = (o.as_dvec3(), d.as_dvec3().normalize(), c.as_dvec3());
    let tm = (c - o).dot(d);
    let dist2 = (o + tm * d - c).length_squared();
    let h2 = r * r - dist2;
    (h2 >= 0.0).then(|| (tm - h2.sqrt(), tm + h2.sqrt(), dist2.sqrt()))
}

#[test]
fn sphere_chord_is_covered_tightly() {
    let mut rng = Rng::new(0x00c0_ffee);
    for _ in 0..40 {
        let center = rng.vec(-2.0, 2.0);
        let radius = rng.range(0.2, 1.5);
        let res = [16, 32, 50, 128][rng.below(4) as usize];
        let field = sphere_field(center, radius);
        let occ = Occupancy::build(&field, res);
        let diag = f64::from((occ.bounds().size() / res as f32).length());
        for i in 0..20 {
            let d = rng.dir();
            // Through the centre for the first ray, then offsets up to half the radius.
            let (u, v) = (
                d.any_orthonormal_vector(),
                d.cross(d.any_orthonormal_vector()),
            );
            let off = if i == 0 {
                0.0
            } else {
                rng.range(0.0, 0.5) * radius
            };
            let ang = rng.range(0.0, std::f32::consts::TAU);
            let target = center + off * (ang.cos() * u + ang.sin() * v);
            let o = target - d * rng.range(radius + 0.5, 6.0);
            let mut seg = Vec::new();
            occ.segments(o, d, 0.0, 20.0, &mut seg);
            let (ta, tb, dist) = chord(o, d, center, f64::from(radius)).unwrap();
            // One segment holds the whole chord (the ray may also clip occupied cells just
            // before or after it, giving short extra segments).
            let seg: Vec<[f64; 2]> = seg.iter().map(|s| s.map(f64::from)).collect();
            assert!(
                seg.iter().any(|s| s[0] <= ta && s[1] >= tb),
                "{seg:?} misses chord [{ta}, {tb}]"
            );
            // Occupied cells meet the ball, so their points are within r + diag of the
            // centre (plus the paddings).
            let reach = f64::from(radius) + diag * 1.01;
            let (lo, hi, _) = chord(o, d, center, reach).unwrap();
            let (a, b) = (seg[0][0], seg[seg.len() - 1][1]);
            assert!(a >= lo && b <= hi, "{seg:?} beyond [{lo}, {hi}]");
            if i == 0 {
                assert!(dist < 1e-4);
                assert!(b - a <= (tb - ta) + 2.0 * diag * 1.01);
            }
        }
    }
}

#[test]
fn origin_inside_an_occupied_cell_starts_at_t0() {
    let field = sphere_field(Vec3::ZERO, 1.0);
    let occ = Occupancy::build(&field, 32);
    let mut seg = Vec::new();
    occ.segments(
        Vec3::new(0.1, 0.2, 0.3),
        Vec3::new(0.0, 0.6, 0.8),
        0.0,
        50.0,
        &mut seg,
    );
    assert_eq!(seg.len(), 1);
    assert_eq!(seg[0][0], 0.0);
    let (_, tb, _) = chord(
        Vec3::new(0.1, 0.2, 0.3),
        Vec3::new(0.0, 0.6, 0.8),
        Vec3::ZERO,
        1.0,
    )
    .unwrap();
    assert!(f64::from(seg[0][1]) >= tb);
}

#[test]
fn empty_bounds_region_is_not_occupied() {
    let field = sphere_field(Vec3::ZERO, 1.0);
    let b = field.bounds();
    assert_eq!(b, Aabb::new(Vec3::splat(-1.0), Vec3::splat(1.0)));
    let occ = Occupancy::build(&field, 40);
    assert!(occ.bounds().min.cmple(b.min).all() && occ.bounds().max.cmpge(b.max).all());
    // The corners of the bounds are farther than a cell diagonal from the ball.
    assert!(!occ.is_occupied_point(Vec3::splat(0.99)));
    assert!(occ.is_occupied_point(Vec3::new(0.0, 0.0, 0.99)));
}

/// Closed boxes of density 1 with an *exact*, unpadded `may_be_occupied`: the occupancy's
/// own paddings are all that protects it from f32 rounding.
struct ExactBoxes(Vec<Aabb>);

impl Field for ExactBoxes {
    fn bounds(&self) -> Aabb {
        self.0.iter().fold(Aabb::EMPTY, |a, b| a.union(b))
    }

    fn density(&self, points: &[Vec3], sigma: &mut [f32]) {
        for (p, s) in points.iter().zip(sigma.iter_mut()) {
            *s = if self.0.iter().any(|b| b.contains(*p)) {
                1.0
            } else {
                0.0
            };
        }
    }

    fn radiance(&self, _: &[Vec3], _: &[Vec3], rgb: &mut [Vec3]) {
        rgb.fill(Vec3::ONE);
    }

    fn may_be_occupied(&self, region: &Aabb) -> bool {
        self.0.iter().any(|b| b.intersects(region))
    }
}

/// A box face a hair (3e-6) past a grid plane, seen from 300 units away: sample positions
/// round by ~3e-5 there, far more than the hair, so a grid without padding would lose the
/// face's first samples.
#[test]
fn far_origin_near_plane_face_is_conservative() {
    let corners = vec![
        Aabb::new(Vec3::splat(-1.0), Vec3::splat(-0.99)),
        Aabb::new(Vec3::splat(0.99), Vec3::splat(1.0)),
    ];
    let res = 32;
    let probe = Occupancy::build(&ExactBoxes(corners.clone()), res);
    let b = probe.bounds();
    let cell = b.size() / res as f32;
    let mut rng = Rng::new(0xfa2);
    for axis in 0..3 {
        let k = 12;
        let plane = b.min[axis] + k as f32 * cell[axis];
        let mut min = Vec3::splat(-0.5);
        min[axis] = plane + 3e-6;
        let face = Aabb::new(min, Vec3::splat(0.5));
        let mut boxes = corners.clone();
        boxes.push(face);
        let field = ExactBoxes(boxes);
        let occ = Occupancy::build(&field, res);
        assert_eq!(occ.bounds(), b);
        for _ in 0..200 {
            let mut target = rng.vec(-0.45, 0.45);
            target[axis] = face.min[axis];
            let mut from = rng.dir();
            from[axis] = -from[axis].abs() - 0.2;
            let o = target + from.normalize() * 300.0;
            let d = (target - o).normalize();
            let mut seg = Vec::new();
            occ.segments(o, d, 0.0, 1000.0, &mut seg);
            let t_face = (face.min[axis] - o[axis]) / d[axis];
            let ts: Vec<f32> = (-2000..2000).map(|i| t_face + i as f32 * 1e-6).collect();
            let pts: Vec<Vec3> = ts.iter().map(|&t| o + t * d).collect();
            let mut sigma = vec![0.0; pts.len()];
            field.density(&pts, &mut sigma);
            assert!(sigma.iter().any(|&s| s > 0.0));
            for (&t, &s) in ts.iter().zip(&sigma) {
                assert!(s == 0.0 || covered(&seg, t), "t = {t} outside {seg:?}");
            }
        }
    }
}

fn boxed(min: Vec3, max: Vec3, density: f32) -> Primitive {
    Primitive {
        shape: Shape::Box { min, max },
        density,
        color: ShColor::constant(Vec3::ONE),
    }
}

/// A ground slab, a post and a ball: wide empty space above a surface, the case the
/// distance-map jumps are for.
fn ground_scene() -> Analytic {
    Analytic {
        primitives: vec![
            boxed(Vec3::new(-2.0, -2.0, -0.4), Vec3::new(2.0, 2.0, 0.0), 20.0),
            boxed(Vec3::new(0.8, -1.2, 0.0), Vec3::new(1.0, -1.0, 2.0), 5.0),
            sphere_field(Vec3::new(-0.7, 0.5, 0.9), 0.3).primitives[0],
        ],
    }
}

/// Rays grazing the slab's top from 0 to 12 cells above it, both ways, some windowed:
/// each jump out of an empty cube must land where the cell-by-cell walk would.
#[test]
fn grazing_rays_over_a_ground_slab() {
    let field = ground_scene();
    let mut rng = Rng::new(0x9a2e);
    for res in [32u32, 64, 128] {
        let occ = Occupancy::build(&field, res);
        let cell_z = occ.bounds().size().z / res as f32;
        let mut hits = 0;
        for i in 0..150 {
            let height = rng.range(-0.5, 12.0) * cell_z;
            let o = Vec3::new(rng.range(-2.5, 2.5), rng.range(-2.5, 2.5), height);
            let horizontal = rng.dir() * Vec3::new(1.0, 1.0, 0.0);
            let slope = [0.0, 1e-4, -1e-3, -0.02, -0.05, -0.2][i % 6];
            let d = (horizontal.normalize() + Vec3::Z * slope).normalize();
            let (t0, t1) = if i % 3 == 0 {
                (rng.range(0.0, 2.0), rng.range(2.0, 6.0))
            } else {
                (0.0, 10.0)
            };
            let seg = check_ray("grazing", &field, &occ, o, d, t0, t1);
            hits += usize::from(!seg.is_empty());
        }
        assert!(hits > 20 && hits < 150, "{hits}");
    }
}

/// Rays starting inside empty cells that touch occupied ones (a cell's width above the
/// slab, beside the post, at the ball's rim), in random directions and windows.
#[test]
fn rays_starting_next_to_occupied_cells() {
    let field = ground_scene();
    let mut rng = Rng::new(0x7e57);
    for res in [24u32, 64] {
        let occ = Occupancy::build(&field, res);
        let cell = occ.bounds().size() / res as f32;
        let starts = [
            Vec3::new(0.3, 0.2, 0.5 * cell.z),
            Vec3::new(0.9, -1.1, 0.0) + Vec3::new(0.1 + 0.5 * cell.x, 0.0, 0.5),
            Vec3::new(-0.7, 0.5, 0.9) + Vec3::new(0.3 + 0.6 * cell.x, 0.0, 0.0),
        ];
        let mut tested = 0;
        for _ in 0..300 {
            let o = starts[rng.below(3) as usize] + rng.vec(-0.5, 0.5) * cell;
            if occ.is_occupied_point(o) {
                continue;
            }
            tested += 1;
            let d = rng.dir();
            let (t0, t1) = if rng.unit() < 0.5 {
                (0.0, 10.0)
            } else {
                (rng.range(0.0, 0.5), rng.range(0.5, 4.0))
            };
            check_ray("next to occupied", &field, &occ, o, d, t0, t1);
        }
        assert!(tested > 100, "{tested}");
    }
}

/// Rays through a solid box (crossed in jumps, emitted whole) and across a grid whose empty
/// middle is far from everything (radii at the cap).
#[test]
fn solid_interiors_and_far_empty_space() {
    let solid = Analytic {
        primitives: vec![boxed(Vec3::splat(-1.0), Vec3::splat(1.0), 3.0)],
    };
    let corners = Analytic {
        primitives: vec![
            sphere_field(Vec3::splat(-1.0), 0.03).primitives[0],
            sphere_field(Vec3::splat(1.0), 0.03).primitives[0],
            sphere_field(Vec3::new(1.0, -1.0, 1.0), 0.03).primitives[0],
        ],
    };
    let mut rng = Rng::new(0x50_11d);
    for (field, res) in [(&solid, 40u32), (&solid, 130), (&corners, 150)] {
        let occ = Occupancy::build(field, res);
        for i in 0..200 {
            let (o, d) = if i % 2 == 0 {
                let o = rng.dir() * 3.0;
                let target = field.primitives[rng.below(field.primitives.len() as u64) as usize]
                    .shape
                    .bounds()
                    .center()
                    + rng.vec(-0.05, 0.05);
                (o, (target - o).normalize())
            } else {
                (rng.vec(-0.9, 0.9), rng.dir())
            };
            let seg = check_ray("solid/far", field, &occ, o, d, 0.0, 10.0);
            if std::ptr::eq(field, &solid) {
                // A convex solid: one piece.
                assert!(seg.len() <= 1, "{seg:?}");
            }
        }
    }
}
