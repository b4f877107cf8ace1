//! The compositing functions against their formulas written out again here, on seeded random
//! premultiplied pixels; their identities; and finite output for alpha 0, NaN and inf input.

use nerfx_core::composite::{
    accumulation_matte, depth_merge, mix, over, rgba_pixels, rgba_planes, shadow_catcher_merge,
    MatteCurve, Rgba,
};
use nerfx_core::image::{Plane, Planes};

const W: u32 = 17;
const H: u32 = 9;
const N: usize = (W * H) as usize;

use crate::common::rng;

/// Seeded random pixels from the tests' one generator.
struct Rng(rng::SplitMix64);

impl Rng {
    fn new(seed: u64) -> Self {
        Rng(rng::SplitMix64::new(seed))
    }

    fn unit(&mut self) -> f32 {
        self.0.unit()
    }

    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.unit()
    }

    /// Premultiplied pixels; about one in eight fully transparent, one in eight opaque.
    fn pixels(&mut self) -> Vec<Rgba> {
        (0..N)
            .map(|_| {
                let a = match (self.unit() * 8.0) as u32 {
                    0 => 0.0,
                    1 => 1.0,
                    _ => self.unit(),
                };
                [a * self.unit(), a * self.unit(), a * self.unit(), a]
            })
            .collect()
    }

    fn plane(&mut self, lo: f32, hi: f32) -> Plane {
        Plane {
            width: W,
            height: H,
            data: (0..N).map(|_| self.range(lo, hi)).collect(),
        }
    }
}

fn planes(px: &[Rgba]) -> Planes {
    rgba_planes(W, H, px).unwrap()
}

/// The one tolerance every comparison here goes through (f32 round-off of a few operations).
fn assert_close(what: &str, got: &Planes, want: &[Rgba]) {
    for (i, (g, w)) in rgba_pixels(got).iter().zip(want).enumerate() {
        for c in 0..4 {
            let tol = 1e-5 * (1.0 + w[c].abs());
            assert!(
                (g[c] - w[c]).abs() <= tol,
                "{what}: pixel {i} channel {c}: got {g:?}, want {w:?}"
            );
        }
    }
}

fn over_ref(a: Rgba, b: Rgba) -> Rgba {
    [
        a[0] + (1.0 - a[3]) * b[0],
        a[1] + (1.0 - a[3]) * b[1],
        a[2] + (1.0 - a[3]) * b[2],
        a[3] + (1.0 - a[3]) * b[3],
    ]
}

#[test]
fn over_and_mix_follow_their_formulas() {
    let mut rng = Rng::new(0x5eed_0001);
    for _ in 0..8 {
        let (a, b) = (rng.pixels(), rng.pixels());
        let want: Vec<Rgba> = a.iter().zip(&b).map(|(&a, &b)| over_ref(a, b)).collect();
        assert_close("over", &over(&planes(&a), &planes(&b)).unwrap(), &want);

        let m = rng.unit();
        let want: Vec<Rgba> = a
            .iter()
            .zip(&b)
            .map(|(r, i)| [0, 1, 2, 3].map(|c| r[c] * m + i[c] * (1.0 - m)))
            .collect();
        assert_close("mix", &mix(&planes(&a), &planes(&b), m).unwrap(), &want);
    }
}

#[test]
fn accumulation_matte_follows_its_formula() {
    let mut rng = Rng::new(0x5eed_0002);
    for _ in 0..8 {
        let black = rng.range(-0.2, 0.4);
        let curve = MatteCurve {
            black_point: black,
            white_point: black + rng.range(0.05, 1.0),
            gamma: rng.range(0.3, 3.0),
            floater_clip: rng.range(0.0, 0.3),
        };
        let matte = rng.plane(0.0, 1.1);
        // The source render is premultiplied by the raw accumulation.
        let source: Vec<Rgba> = matte
            .data
            .iter()
            .map(|&m| [m * rng.unit(), m * rng.unit(), m * rng.unit(), 1.0])
            .collect();
        let want: Vec<Rgba> = source
            .iter()
            .zip(&matte.data)
            .map(|(s, &m)| {
                let t = ((m - curve.black_point) / (curve.white_point - curve.black_point))
                    .clamp(0.0, 1.0);
                let mut a = t.powf(1.0 / curve.gamma);
                if a < curve.floater_clip {
                    a = 0.0;
                }
                let k = if m > 0.0 { a / m } else { 1.0 };
                [s[0] * k, s[1] * k, s[2] * k, a]
            })
            .collect();
        let got = accumulation_matte(&planes(&source), &matte, &curve).unwrap();
        assert_close("accumulation matte", &got, &want);
        // Consistently premultiplied: colour ≤ alpha wherever the source colour ≤ m.
        for p in rgba_pixels(&got) {
            assert!(p[..3].iter().all(|&c| c <= p[3] + 1e-5), "{p:?}");
        }
    }
}

#[test]
fn identity_matte_keeps_the_render_and_sets_alpha_to_the_accumulation() {
    let mut rng = Rng::new(0x5eed_0003);
    let matte = rng.plane(0.0, 1.0);
    let source: Vec<Rgba> = matte
        .data
        .iter()
        .map(|&m| [m * 0.5, m * 0.25, m, 1.0])
        .collect();
    let want: Vec<Rgba> = source
        .iter()
        .zip(&matte.data)
        .map(|(s, &m)| [s[0], s[1], s[2], m])
        .collect();
    let got = accumulation_matte(&planes(&source), &matte, &MatteCurve::default()).unwrap();
    assert_close("identity matte", &got, &want);
}

#[test]
fn shadow_catcher_merge_follows_its_formula() {
    let mut rng = Rng::new(0x5eed_0004);
    for _ in 0..8 {
        let (a, b) = (rng.pixels(), rng.pixels());
        let shadow = rng.plane(0.0, 1.0);
        let opacity = rng.unit();
        let tint = [rng.unit(), rng.unit(), rng.unit()];
        let want: Vec<Rgba> = (0..N)
            .map(|i| {
                let s = shadow.data[i];
                let darkened = [
                    b[i][0] * (1.0 - opacity * s * (1.0 - tint[0])),
                    b[i][1] * (1.0 - opacity * s * (1.0 - tint[1])),
                    b[i][2] * (1.0 - opacity * s * (1.0 - tint[2])),
                    b[i][3],
                ];
                over_ref(a[i], darkened)
            })
            .collect();
        let got = shadow_catcher_merge(&planes(&a), &shadow, &planes(&b), opacity, tint);
        assert_close("shadow catcher merge", &got.unwrap(), &want);
    }
}

#[test]
fn depth_merge_follows_its_formula() {
    let mut rng = Rng::new(0x5eed_0005);
    for _ in 0..8 {
        let (a, b) = (rng.pixels(), rng.pixels());
        let (za, zb) = (rng.plane(1.0, 3.0), rng.plane(1.0, 3.0));
        let softness = rng.range(0.01, 1.0);
        let want: Vec<Rgba> = (0..N)
            .map(|i| {
                let d = zb.data[i] - za.data[i];
                let x = ((d + softness / 2.0) / softness).clamp(0.0, 1.0);
                let w = x * x * (3.0 - 2.0 * x);
                let (ab, ba) = (over_ref(a[i], b[i]), over_ref(b[i], a[i]));
                [0, 1, 2, 3].map(|c| w * ab[c] + (1.0 - w) * ba[c])
            })
            .collect();
        let got = depth_merge(&planes(&a), &za, &planes(&b), &zb, softness).unwrap();
        assert_close("depth merge", &got, &want);
    }
}

#[test]
fn identities() {
    let mut rng = Rng::new(0x5eed_0006);
    let (a, b) = (rng.pixels(), rng.pixels());
    let (pa, pb) = (planes(&a), planes(&b));
    let clear = planes(&[[0.0; 4]; N]);
    assert_close("transparent A over B", &over(&clear, &pb).unwrap(), &b);
    assert_close("mix 0", &mix(&pa, &pb, 0.0).unwrap(), &b);
    assert_close("mix 1", &mix(&pa, &pb, 1.0).unwrap(), &a);

    let a_over_b: Vec<Rgba> = a.iter().zip(&b).map(|(&a, &b)| over_ref(a, b)).collect();
    // A nearer everywhere, by more than half the softness band; B sometimes at "nothing".
    let za = rng.plane(1.0, 2.0);
    let zb = Plane {
        data: (0..N)
            .map(|i| match i % 3 {
                0 => f32::INFINITY,
                1 => 1.0e10,
                _ => za.data[i] + 0.6,
            })
            .collect(),
        ..za.clone()
    };
    for softness in [0.0, 0.5, 1.0] {
        let got = depth_merge(&pa, &za, &pb, &zb, softness).unwrap();
        assert_close("depth merge, A nearer", &got, &a_over_b);
    }
    let no_shadow = rng.plane(0.0, 1.0);
    let got = shadow_catcher_merge(&pa, &no_shadow, &pb, 0.0, [0.2, 0.3, 0.4]).unwrap();
    assert_close("shadow opacity 0", &got, &a_over_b);
    let no_shadow = Plane::filled(W, H, 0.0);
    let got = shadow_catcher_merge(&pa, &no_shadow, &pb, 1.0, [0.0; 3]).unwrap();
    assert_close("shadow alpha 0", &got, &a_over_b);
}

#[test]
fn alpha_zero_nan_and_inf_give_finite_output() {
    let bad = [f32::NAN, f32::INFINITY, -f32::INFINITY, 0.0];
    let px: Vec<Rgba> = (0..N)
        .map(|i| {
            [
                bad[i % 4],
                bad[(i + 1) % 4],
                bad[(i + 2) % 4],
                bad[(i + 3) % 4],
            ]
        })
        .collect();
    let p = planes(&px);
    let zero = Plane::filled(W, H, 0.0);
    let weird = Plane {
        data: (0..N).map(|i| bad[i % 4]).collect(),
        ..zero.clone()
    };
    let outputs = [
        over(&p, &p).unwrap(),
        mix(&p, &p, 0.5).unwrap(),
        accumulation_matte(&p, &zero, &MatteCurve::default()).unwrap(),
        accumulation_matte(&p, &weird, &MatteCurve::default()).unwrap(),
        shadow_catcher_merge(&p, &weird, &p, 1.0, [0.0; 3]).unwrap(),
        depth_merge(&p, &weird, &p, &zero, 0.5).unwrap(),
        depth_merge(&p, &weird, &p, &weird, 0.0).unwrap(),
    ];
    for (k, out) in outputs.iter().enumerate() {
        for px in rgba_pixels(out) {
            assert!(px.iter().all(|v| v.is_finite()), "output {k}: {px:?}");
        }
        // Sanitised, not merely hidden by rgba_pixels: the planes themselves are finite.
        let rgb = out.rgb.as_ref().unwrap();
        let alpha = out.alpha.as_ref().unwrap();
        assert!(rgb
            .iter()
            .chain([alpha])
            .all(|p| p.data.iter().all(|v| v.is_finite())));
    }
    // Where the matte is 0 (alpha 0) the colour is the (sanitised) source, not a 0/0.
    let src = planes(&[[0.0, 0.0, 0.0, 0.0]; N]);
    let got = accumulation_matte(&src, &zero, &MatteCurve::default()).unwrap();
    assert_close("matte 0", &got, &[[0.0; 4]; N]);
}

#[test]
fn mismatched_sizes_and_bad_parameters_are_refused() {
    let a = planes(&[[0.0; 4]; N]);
    let small = rgba_planes(1, 1, &[[0.0; 4]]).unwrap();
    let e = over(&a, &small).unwrap_err().to_string();
    assert!(e.contains("over") && e.contains("B is 1×1"), "{e}");
    let z = Plane::filled(W, H, 1.0);
    assert!(mix(&a, &a, 1.5).is_err());
    assert!(depth_merge(&a, &z, &a, &z, -1.0).is_err());
    assert!(depth_merge(&a, &z, &a, &z, f32::NAN).is_err());
    let e = shadow_catcher_merge(&a, &z, &a, 2.0, [0.0; 3]).unwrap_err();
    assert!(e.to_string().contains("opacity"), "{e}");
}
