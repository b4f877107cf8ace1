#!/usr/bin/env python3
"""Writes crates/core/src/field/analytic/erf/tables.rs: the polynomial tables of the closed-form
integrator's error functions (crates/core/src/field/analytic/erf/mod.rs), fitted here with mpmath at 40
digits.

- erfcx(x) = exp(x^2) erfc(x), x >= 0, as y*g(y) with y = 4/(4 + x) in (0, 1]: g is smooth on
  [0, 1] (g(0) = 1/(4 sqrt(pi)), the tail's limit), cut into INTERVALS equal pieces of y, each a
  polynomial of degree DEGREE in u in [-1, 1] (Chebyshev interpolation, then monomials).
- erf(x) = x*h(x^2) for 0 <= x < 1/2, h a polynomial of degree SMALL_DEGREE in u = 8x^2 - 1.

Run from the repository root: python3 scripts/erf_tables.py
Checks each table at 20 000 points against mpmath in double arithmetic before writing it.
"""
import random

import mpmath as mp

mp.mp.dps = 40
INTERVALS, DEGREE = 64, 6
SMALL_DEGREE = 9
OUT = "crates/core/src/field/analytic/erf/tables.rs"


def g(y):
    """erfcx(4(1 - y)/y)/y, and its limit at y = 0."""
    y = mp.mpf(y)
    if y == 0:
        return 1 / (4 * mp.sqrt(mp.pi))
    x = 4 * (1 - y) / y
    return mp.exp(x * x) * mp.erfc(x) / y


def h(s):
    """erf(x)/x at s = x^2, and its limit at 0."""
    s = mp.mpf(s)
    if s == 0:
        return 2 / mp.sqrt(mp.pi)
    x = mp.sqrt(s)
    return mp.erf(x) / x


def monomials(f, lo, hi, degree):
    """f's Chebyshev interpolant on [lo, hi] as monomial coefficients in u in [-1, 1]."""
    n = degree + 1
    nodes = [mp.cos(mp.pi * (k + mp.mpf(1) / 2) / n) for k in range(n)]
    values = [f((lo + hi) / 2 + (hi - lo) / 2 * u) for u in nodes]
    cheb = [
        2 * sum(values[k] * mp.cos(mp.pi * j * (k + mp.mpf(1) / 2) / n) for k in range(n)) / n
        for j in range(n)
    ]
    cheb[0] /= 2
    t = [[mp.mpf(1)], [mp.mpf(0), mp.mpf(1)]]
    for j in range(2, n):
        up = [mp.mpf(0)] + [2 * v for v in t[j - 1]]
        down = t[j - 2] + [mp.mpf(0)] * (len(up) - len(t[j - 2]))
        t.append([p - q for p, q in zip(up, down)])
    out = [mp.mpf(0)] * n
    for j in range(n):
        for i, v in enumerate(t[j]):
            out[i] += cheb[j] * v
    return [float(c) for c in out]


def horner(coefficients, u):
    acc = 0.0
    for c in reversed(coefficients):
        acc = acc * u + c
    return acc


def erfcx(table, x):
    y = 4.0 / (4.0 + x)
    scaled = y * INTERVALS
    i = min(int(scaled), INTERVALS - 1)
    return y * horner(table[i], 2.0 * (scaled - i) - 1.0)


def main():
    table = [
        monomials(g, mp.mpf(i) / INTERVALS, mp.mpf(i + 1) / INTERVALS, DEGREE)
        for i in range(INTERVALS)
    ]
    # h on s in [0, 1/4]: s = (1 + u)/8.
    small = monomials(h, mp.mpf(0), mp.mpf(1) / 4, SMALL_DEGREE)
    rng = random.Random(1)
    worst = 0.0
    for _ in range(20_000):
        x = rng.choice([rng.uniform(0, 8), 10 ** rng.uniform(-3, 12)])
        exact = mp.exp(mp.mpf(x) ** 2) * mp.erfc(x)
        worst = max(worst, float(abs(erfcx(table, x) - exact) / exact))
    worst_small = 0.0
    for _ in range(20_000):
        x = rng.uniform(1e-9, 0.5)
        exact = mp.erf(x)
        worst_small = max(worst_small, float(abs(x * horner(small, 8 * x * x - 1) - exact) / exact))
    assert worst < 2e-15 and worst_small < 2e-15, (worst, worst_small)
    rows = ",\n".join("    [" + ", ".join(repr(c) for c in row) + "]" for row in table)
    with open(OUT, "w") as f:
        f.write(
            f"""//! Polynomial tables of the error functions in [`erf`](super), written by
//! `scripts/erf_tables.py` (mpmath at 40 digits; its checks found relative errors of at most
//! {worst:.1e} for `erfcx` and {worst_small:.1e} for `erf` below 1/2). Do not edit by hand.

/// Pieces of `y = 4/(4 + x)` in `(0, 1]`, equal.
pub(super) const INTERVALS: usize = {INTERVALS};

/// Per piece, the monomial coefficients (constant first) in `u ∈ [−1, 1]` across it of
/// `erfcx(x)/y`.
#[rustfmt::skip]
pub(super) const ERFCX: [[f64; {DEGREE + 1}]; INTERVALS] = [
{rows},
];

/// The monomial coefficients (constant first) in `u = 8x² − 1` of `erf(x)/x` for
/// `0 ≤ x < 1/2`.
#[rustfmt::skip]
pub(super) const ERF_SMALL: [f64; {SMALL_DEGREE + 1}] = [{", ".join(repr(c) for c in small)}];
"""
        )
    print(f"wrote {OUT}: erfcx within {worst:.2e}, small erf within {worst_small:.2e} (relative)")


if __name__ == "__main__":
    main()
