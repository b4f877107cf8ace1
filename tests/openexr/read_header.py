"""Prints an EXR's header as JSON, read by OpenEXR's own library (its Python bindings), for
tests/outputs/exr_camera.rs.

    python3 read_header.py FILE.exr

Matrices (Imath M44f) become their 16 numbers in stored order (row by row), vectors and
chromaticities lists of numbers, rationals [numerator, denominator], strings themselves;
other values their repr.
"""

import json
import sys
from fractions import Fraction

import numpy as np
import OpenEXR


def plain(value):
    if isinstance(value, (str, int, float, bool)) or value is None:
        return value
    if isinstance(value, bytes):
        return value.decode("utf-8")
    if isinstance(value, Fraction):
        return [value.numerator, value.denominator]
    if hasattr(value, "numerator") and hasattr(value, "denominator"):
        return [int(value.numerator), int(value.denominator)]
    if isinstance(value, (tuple, list, np.ndarray)):
        try:
            return [float(v) for v in np.asarray(value, dtype=np.float64).ravel()]
        except (TypeError, ValueError):
            return [plain(v) for v in value]
    return repr(value)


def main(path):
    with OpenEXR.File(path) as f:
        header = dict(f.header())
    print(json.dumps({k: plain(v) for k, v in header.items() if k != "channels"}))


if __name__ == "__main__":
    main(sys.argv[1])
