"""OpenColorIO's own conversion of a linear Rec.709 EXR, for tests/outputs/color_spaces.rs.

    python3 convert.py LINEAR.exr CONVERTED.exr "OCIO colour space name"

Reads LINEAR.exr (premultiplied linear Rec.709) and CONVERTED.exr (what nerfx wrote in the
named space) with OpenEXR's own library, converts LINEAR.exr's colour with OpenColorIO's
built-in CG configuration (ocio://cg-config-latest) from "Linear Rec.709 (sRGB)" to the named
space, on unpremultiplied colour when the space is display-encoded (premultiplied again
after), and prints JSON: the PSNR of CONVERTED against that reference (peak: the larger of 1
and the reference's largest value), and CONVERTED's chromaticities attribute.
"""

import json
import sys

import numpy as np
import OpenEXR
import PyOpenColorIO as ocio


def rgba(path):
    with OpenEXR.File(path, separate_channels=True) as f:
        channels = f.channels()
        header = dict(f.header())
        planes = [np.asarray(channels[c].pixels, dtype=np.float64) for c in "RGBA"]
    return np.stack(planes[:3], axis=-1), planes[3], header


def main(linear_path, converted_path, space):
    linear, alpha, _ = rgba(linear_path)
    converted, _, header = rgba(converted_path)
    config = ocio.Config.CreateFromFile("ocio://cg-config-latest")
    processor = config.getProcessor("Linear Rec.709 (sRGB)", space).getDefaultCPUProcessor()
    encoded = config.getColorSpace(space).getEncoding() == "sdr-video"
    a = np.where(alpha > 0, alpha, 1.0)[..., None] if encoded else 1.0
    pixels = np.ascontiguousarray((linear / a).reshape(-1, 3), dtype=np.float32)
    processor.applyRGB(pixels)
    reference = pixels.reshape(linear.shape).astype(np.float64) * a
    mse = float(np.mean((converted - reference) ** 2))
    peak = max(1.0, float(np.max(np.abs(reference))))
    psnr = float("inf") if mse == 0 else 10 * np.log10(peak * peak / mse)
    c = header.get("chromaticities")
    chroma = None if c is None else [float(v) for v in np.asarray(c, dtype=np.float64).ravel()]
    print(json.dumps({"psnr": psnr if np.isfinite(psnr) else 1e9, "chromaticities": chroma}))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], sys.argv[3])
