//! The compositing weights of a run of consecutive samples along one ray, as nerfstudio's
//! `get_weights` gives them: with `δ_j = t_{j+1} − t_j`,
//! `w_j = (1 − e^{−σ_j δ_j})·T_j` and `T_{j+1} = T_j·e^{−σ_j δ_j}`, the transmittance
//! carried as a product (one exponential per sample) and `1 − e^{−σδ}` taken as `−expm1`
//! (exact for thin samples).
//!
//! The exponentials of a run are taken together, four at a time with AVX2 and FMA where the
//! CPU has them ([`decays`]): within a few units in the last place of libm's `expm1`, and
//! cheaper than a call per sample, which the product chain waited on.
//!
//! Example: `σ = (0, ln 2, ln 2)` over unit intervals from `T = 1` gives `w = (0, ½, ¼)`
//! and leaves `T = ¼`.

/// Samples whose exponentials are taken together.
const RUN: usize = 16;

/// The weights of the samples of densities `sigma` on the intervals between consecutive
/// distances `t` (one more than `sigma`) into `weights`, from and updating the ray's
/// `transmittance`. Densities are [`sanitised`].
#[inline]
pub(super) fn weigh_run(sigma: &[f32], t: &[f64], transmittance: &mut f64, weights: &mut [f64]) {
    debug_assert!(t.len() == sigma.len() + 1 && weights.len() == sigma.len());
    let mut e = [0.0f64; RUN];
    let runs = sigma.chunks(RUN).zip(weights.chunks_mut(RUN));
    for (k, (sigma, weights)) in runs.enumerate() {
        let e = &mut e[..sigma.len()];
        decays(sigma, &t[k * RUN..=k * RUN + sigma.len()], e);
        for (w, &e) in weights.iter_mut().zip(e.iter()) {
            *w = -e * *transmittance;
            *transmittance *= 1.0 + e;
        }
    }
}

/// NaN, infinite or negative densities count as empty (as in the marcher).
#[inline]
pub(super) fn sanitised(sigma: f32) -> f64 {
    if sigma.is_finite() && sigma > 0.0 {
        f64::from(sigma)
    } else {
        0.0
    }
}

/// `e_j = e^{−σ_j δ_j} − 1` of the samples of densities `sigma` ([`sanitised`]) on the
/// intervals between consecutive distances `t` (one more than `sigma`).
fn decays(sigma: &[f32], t: &[f64], e: &mut [f64]) {
    #[cfg(target_arch = "x86_64")]
    if is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma") {
        // SAFETY: the CPU has AVX2 and FMA.
        unsafe { decays_avx2(sigma, t, e) };
        return;
    }
    for ((e, &sigma), t) in e.iter_mut().zip(sigma).zip(t.windows(2)) {
        *e = (-sanitised(sigma) * (t[1] - t[0])).exp_m1();
    }
}

/// [`decays`] four samples at a time, computed in registers from the densities and
/// distances (the exponents stored one by one and loaded as a vector would wait on the
/// stores), the last `len mod 4` through masked loads and stores.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn decays_avx2(sigma: &[f32], t: &[f64], e: &mut [f64]) {
    use std::arch::x86_64::*;
    let n = sigma.len();
    assert!(t.len() == n + 1 && e.len() == n);
    let whole = n / 4 * 4;
    for j in (0..whole).step_by(4) {
        // SAFETY: `j + 4 ≤ n`, so four values from `j` lie in `sigma`, `e` and `t`, and from
        // `j + 1` in `t`.
        unsafe {
            let sigma = _mm_loadu_ps(sigma.as_ptr().add(j));
            let t0 = _mm256_loadu_pd(t.as_ptr().add(j));
            let t1 = _mm256_loadu_pd(t.as_ptr().add(j + 1));
            _mm256_storeu_pd(e.as_mut_ptr().add(j), decay4(sigma, t0, t1));
        }
    }
    let rest = n - whole;
    if rest > 0 {
        let lanes = _mm256_cmpgt_epi64(
            _mm256_set1_epi64x(rest as i64),
            _mm256_setr_epi64x(0, 1, 2, 3),
        );
        let lanes32 = _mm_cmpgt_epi32(_mm_set1_epi32(rest as i32), _mm_setr_epi32(0, 1, 2, 3));
        // SAFETY: the masks touch only the `rest` values from `whole` (from `whole + 1` in
        // `t`), which lie in the slices; the others load as zeros.
        unsafe {
            let sigma = _mm_maskload_ps(sigma.as_ptr().add(whole), lanes32);
            let t0 = _mm256_maskload_pd(t.as_ptr().add(whole), lanes);
            let t1 = _mm256_maskload_pd(t.as_ptr().add(whole + 1), lanes);
            _mm256_maskstore_pd(e.as_mut_ptr().add(whole), lanes, decay4(sigma, t0, t1));
        }
    }
}

/// `e^{−σδ} − 1` of four samples of densities `sigma` between the distances `t0` and `t1`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
fn decay4(
    sigma: std::arch::x86_64::__m128,
    t0: std::arch::x86_64::__m256d,
    t1: std::arch::x86_64::__m256d,
) -> std::arch::x86_64::__m256d {
    use std::arch::x86_64::*;
    let sigma = _mm256_cvtps_pd(sigma);
    // `sanitised`: the finite positive densities, zero for the rest (NaN compares false).
    let valid = _mm256_and_pd(
        _mm256_cmp_pd::<_CMP_GT_OQ>(sigma, _mm256_setzero_pd()),
        _mm256_cmp_pd::<_CMP_LT_OQ>(sigma, _mm256_set1_pd(f64::INFINITY)),
    );
    let sigma = _mm256_and_pd(sigma, valid);
    let x = _mm256_mul_pd(
        _mm256_xor_pd(sigma, _mm256_set1_pd(-0.0)),
        _mm256_sub_pd(t1, t0),
    );
    exp_m1_4(x)
}

/// `eˣ − 1` of four lanes, for `x ≤ 700`: `x = k·ln 2 + r` with `k` the nearest integer
/// to `x/ln 2` (`|r| ≤ ln 2 / 2`, `ln 2` in two parts so that `r` is exact to a few ulp of
/// its own), `eʳ − 1` as its Taylor series to `r¹³/13!` (the rest below `2⁻⁵⁶·|r|`), then
/// `eˣ − 1 = 2ᵏ·(eʳ − 1) + (2ᵏ − 1)` in one rounding (for `k = 0` exactly `eʳ − 1`, so
/// small `x` keep their relative accuracy). Below `x = −40`, `eˣ` is under half an ulp of
/// 1 and the result is −1.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
fn exp_m1_4(v: std::arch::x86_64::__m256d) -> std::arch::x86_64::__m256d {
    use std::arch::x86_64::*;
    /// `1/n!` for `n` from 13 down to 2.
    const TAYLOR: [f64; 12] = {
        let mut c = [0.0; 12];
        let mut i = 0;
        while i < 12 {
            let mut f = 1.0;
            let mut n = 2;
            while n <= 13 - i {
                f *= n as f64;
                n += 1;
            }
            c[i] = 1.0 / f;
            i += 1;
        }
        c
    };
    // `ln 2` split: its high part (0.6931471803…) has 32 significant bits, so `k·LN2_HI`
    // is exact; the low part (1.9082149…·10⁻¹⁰) is the rest to double precision.
    const LN2_HI: f64 = f64::from_bits(0x3fe6_2e42_fee0_0000);
    const LN2_LO: f64 = f64::from_bits(0x3dea_39ef_3579_3c76);
    let v = _mm256_max_pd(v, _mm256_set1_pd(-40.0));
    let k = _mm256_round_pd::<{ _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC }>(_mm256_mul_pd(
        v,
        _mm256_set1_pd(std::f64::consts::LOG2_E),
    ));
    let r = _mm256_fnmadd_pd(k, _mm256_set1_pd(LN2_HI), v);
    let r = _mm256_fnmadd_pd(k, _mm256_set1_pd(LN2_LO), r);
    // 1 + r/2 + r²/6 + … + r¹²/13!, then times r.
    // A loop, not `fold`: its closure would not have the target features.
    let mut series = _mm256_setzero_pd();
    for c in TAYLOR {
        series = _mm256_fmadd_pd(series, r, _mm256_set1_pd(c));
    }
    let series = _mm256_fmadd_pd(series, r, _mm256_set1_pd(1.0));
    let p = _mm256_mul_pd(series, r);
    // `2ᵏ` from its exponent bits (`k ≥ −58` after the clamp).
    let k = _mm256_cvtepi32_epi64(_mm256_cvtpd_epi32(k));
    let bits = _mm256_slli_epi64::<52>(_mm256_add_epi64(k, _mm256_set1_epi64x(1023)));
    let scale = _mm256_castsi256_pd(bits);
    _mm256_fmadd_pd(scale, p, _mm256_sub_pd(scale, _mm256_set1_pd(1.0)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn batched_exponentials_match_libm() {
        // Seeded densities of 10⁻²⁰ to 60 (and a few larger, empty and invalid ones) over
        // unit intervals, in runs of every length modulo four (the last few through masked
        // loads): libm's `expm1` of the same exponents to within three units in the last
        // place.
        let mut rng = crate::rng::SplitMix64::new(11);
        let mut sigma: Vec<f32> = (0..1001)
            .map(|_| 10f64.powf(-20.0 + 21.78 * f64::from(rng.unit())) as f32)
            .collect();
        sigma.extend([0.0, 0.3, 0.35, 40.0, 41.0, 745.0, 1e9]);
        sigma[3] = f32::NAN;
        sigma[4] = -2.0;
        sigma[5] = f32::INFINITY;
        let t: Vec<f64> = (0..=sigma.len()).map(|j| j as f64).collect();
        for n in (1..=8).chain([sigma.len() - 1, sigma.len()]) {
            let (sigma, t) = (&sigma[sigma.len() - n..], &t[t.len() - n - 1..]);
            let mut got = vec![0.0; n];
            decays(sigma, t, &mut got);
            for (j, (&s, &got)) in sigma.iter().zip(&got).enumerate() {
                let x = -sanitised(s) * (t[j + 1] - t[j]);
                let want = x.exp_m1();
                let ulp = f64::EPSILON * want.abs();
                assert!(
                    (got - want).abs() <= 3.0 * ulp,
                    "run of {n}: expm1({x:e}) = {want:e}, got {got:e}"
                );
            }
        }
    }

    #[test]
    fn weights_follow_the_doc_example() {
        let ln2 = std::f32::consts::LN_2;
        let (mut transmittance, mut w) = (1.0, [0.0; 3]);
        weigh_run(
            &[0.0, ln2, ln2],
            &[0.0, 1.0, 2.0, 3.0],
            &mut transmittance,
            &mut w,
        );
        for (got, want) in w.iter().chain([&transmittance]).zip([0.0, 0.5, 0.25, 0.25]) {
            assert!((got - want).abs() < 1e-7, "{w:?} {transmittance}");
        }
    }

    #[test]
    fn weights_in_runs_are_the_per_sample_chain() {
        // 37 seeded samples (longer than a run, not a multiple of it), invalid densities
        // among them: the same weights as the chain sample by sample with libm's expm1,
        // to rounding.
        let mut rng = crate::rng::SplitMix64::new(5);
        let mut next = || f64::from(rng.unit());
        let mut sigma: Vec<f32> = (0..37).map(|_| (20.0 * next()) as f32).collect();
        sigma[3] = f32::NAN;
        sigma[9] = -1.0;
        sigma[20] = f32::INFINITY;
        let mut t = vec![0.5];
        for _ in 0..37 {
            t.push(t.last().unwrap() + 0.1 * next());
        }
        let (mut transmittance, mut got) = (1.0, vec![0.0; 37]);
        weigh_run(&sigma, &t, &mut transmittance, &mut got);
        let mut want_t = 1.0;
        for (j, &s) in sigma.iter().enumerate() {
            let e = (-sanitised(s) * (t[j + 1] - t[j])).exp_m1();
            let want = -e * want_t;
            want_t *= 1.0 + e;
            assert!(
                (got[j] - want).abs() <= 1e-14 * want.abs(),
                "{j}: {} {want}",
                got[j]
            );
        }
        assert!((transmittance - want_t).abs() <= 1e-14 * want_t);
        assert!(transmittance > 0.0 && transmittance < 1.0);
    }
}
