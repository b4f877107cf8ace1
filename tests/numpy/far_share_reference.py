"""Independent values of a linear piece's far share, from its definition, not from nerfx's Rust.

    python3 far_share_reference.py > OUT.txt

A piece of length delta whose density goes linearly from sigma0 at its near end to sigma1 at its
far end sends its light from the mean position

    share = int_0^1 u w(u) du / int_0^1 w(u) du,
    w(u) = (tau0 + (tau1 - tau0) u) exp(-(tau0 u + (tau1 - tau0) u^2 / 2)),  tau = sigma delta,

integrated here with mpmath's quadrature at 30 digits (split where the light is: the weight
falls off over about 1 / max(tau0, tau1) of the piece). Cases: a grid of optical thicknesses
from 0 to 1e9 at both ends, equal and zero ends, seeded random pairs over that range, and
pieces whose density falls steeply across them (tau0 in [8, 14], tau1 < 1).

OUT: one case a line, `sigma0 sigma1 delta share`, each a float's shortest exact repr.
Needs mpmath.
"""

import random

import mpmath

mpmath.mp.dps = 30


def share(sigma0, sigma1, delta):
    t0 = mpmath.mpf(sigma0) * mpmath.mpf(delta)
    t1 = mpmath.mpf(sigma1) * mpmath.mpf(delta)

    def weight(u):
        return (t0 + (t1 - t0) * u) * mpmath.exp(-(t0 * u + (t1 - t0) * u * u / 2))

    top = max(t0, t1)
    cuts = [mpmath.mpf(0)]
    for c in (0.25, 1, 4, 16, 64):
        if top > 0 and c / top < 1:
            cuts.append(c / top)
    cuts.append(mpmath.mpf(1))
    num = mpmath.quad(lambda u: u * weight(u), cuts)
    den = mpmath.quad(weight, cuts)
    return num / den


def cases():
    taus = [0.0, 1e-12, 1e-6, 1e-3, 0.01, 0.05, 0.1, 0.3, 1.0, 3.0, 8.0, 14.0, 30.0, 100.0,
            1e3, 1e6, 1e9]
    for t0 in taus:
        for t1 in taus:
            if t0 + t1 > 0:
                yield t0, t1, 1.0
    # The same thicknesses from other densities and lengths.
    for t0, t1 in [(0.3, 2.0), (13.0, 13.0), (12.0, 0.4), (1e-5, 3e-5)]:
        for delta in (1e-9, 1e-3, 7.5, 1e4):
            yield t0 / delta, t1 / delta, delta
    rng = random.Random(20261127)
    for _ in range(200):
        # Any mean thickness from 1e-12 to 1e9, any split between the ends.
        mean = 10.0 ** rng.uniform(-12.0, 9.0)
        f = rng.random()
        yield 2.0 * mean * f, 2.0 * mean * (1.0 - f), 1.0
    for _ in range(100):
        # Thicknesses of order one, where every term of the share matters.
        yield 10.0 ** rng.uniform(-3.0, 1.5), 10.0 ** rng.uniform(-3.0, 1.5), rng.uniform(0.1, 2.0)
    for _ in range(100):
        # Density falling steeply across an opaque piece.
        yield rng.uniform(8.0, 14.0), rng.uniform(0.0, 1.0), 1.0


def main():
    for sigma0, sigma1, delta in cases():
        value = share(sigma0, sigma1, delta)
        print(repr(sigma0), repr(sigma1), repr(delta), repr(float(value)))


if __name__ == "__main__":
    main()
