#!/usr/bin/env python3
"""Writes tests/fixtures/pidng/: DNGs as PiDNG 4.x writes them when it is used the way its
README shows, each beside its raw twin (the same mosaic as little-endian u16 `.raw` plus the
JSON sidecar `l3` reads). tests/io/pidng_fixtures.rs checks that each DNG decodes to its twin
and that `l3 render` gives the same PNG bytes for both.

    python3 -m pip install 'pidng>=4,<5' numpy
    cargo build --bin l3
    python3 scripts/pidng_fixtures.py          # rewrites tests/fixtures/pidng/

What PiDNG writes and other writers often do not (the reader's leniencies, docs/dng.md):
  - no CFAPlaneColor: PiDNG leaves it to the caller and its README does not set it, so an
    RGBW file has a white (6) in CFAPattern and no plane list;
  - DNGVersion and DNGBackwardVersion twice: PiDNG writes 1.4 and 1.0 itself and again what
    the caller sets (here 1.4 and 1.2);
  - no UniqueCameraModel in rgbw_pidng.dng (the README sets Make and Model only); none of
    CFALayout, BlackLevelRepeatDim, DefaultCropOrigin/Size, ActiveArea.

Files:
  rgbw_pidng.dng/.raw/.json    64x48, 16 bits, CFAPattern 0 1 6 2 (R G / W B), BlackLevel
                               4096, WhiteLevel 65535, AsShotNeutral R G B W, illuminant A
  bayer_sony.dng/.raw/.json    32x24, 14 bits stored in 16, RGGB, Make "SONY", Model
                               "ILCE-9", UniqueCameraModel "Sony ILCE-9", illuminant D65
  sony_macbeth.dng/.raw/.json  192x128: `l3 simulate --sensor bayer-sony-ilce-9 --scene
                               macbeth --illuminant D65 --seed 1` (the binary in $L3, default
                               target/debug/l3), its codes taken to 14 bits (black 512, white
                               16383), AsShotNeutral the white patch's response; the
                               names as bayer_sony.dng's
"""

import json
import os
import subprocess
import tempfile

import numpy as np
import pidng
from pidng.core import RAW2DNG, DNGTags, Tag
from pidng.defs import CalibrationIlluminant, DNGVersion, PhotometricInterpretation

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
OUT = os.path.join(ROOT, "tests", "fixtures", "pidng")


def mosaic(w, h, black, white, offsets):
    """A deterministic mosaic: a diagonal gradient from black to white, a per-CFA-position
    offset (the pattern), and one saturated pixel."""
    y, x = np.mgrid[0:h, 0:w]
    ramp = (x / (w - 1) + y / (h - 1)) / 2.0  # 0 … 1
    v = black + ramp * 0.8 * (white - black)
    v += np.array(offsets, dtype=np.float64).reshape(2, 2)[y % 2, x % 2]
    v = np.clip(np.round(v), black, white).astype(np.uint16)
    v[h // 2, w // 2] = white
    return v


def tags(w, h, bits, pattern, black, white, neutral, illuminant):
    """The tags of PiDNG's README example (one tile of the whole image)."""
    t = DNGTags()
    t.set(Tag.ImageWidth, w)
    t.set(Tag.ImageLength, h)
    t.set(Tag.TileWidth, w)
    t.set(Tag.TileLength, h)
    t.set(Tag.PhotometricInterpretation, PhotometricInterpretation.Color_Filter_Array)
    t.set(Tag.SamplesPerPixel, 1)
    t.set(Tag.BitsPerSample, bits)
    t.set(Tag.CFARepeatPatternDim, [2, 2])
    t.set(Tag.CFAPattern, pattern)
    t.set(Tag.BlackLevel, black)
    t.set(Tag.WhiteLevel, white)
    t.set(Tag.AsShotNeutral, neutral)
    t.set(Tag.CalibrationIlluminant1, illuminant)
    t.set(Tag.DNGVersion, DNGVersion.V1_4)
    t.set(Tag.DNGBackwardVersion, DNGVersion.V1_2)
    return t


def write(stem, t, data, cfa, black, white, note):
    r = RAW2DNG()
    r.options(t, path=OUT, compress=False)
    r.convert(data, filename=stem)
    h, w = data.shape
    data.astype("<u2").tofile(os.path.join(OUT, stem + ".raw"))
    meta = {
        "width": int(w),
        "height": int(h),
        "cfa": cfa,
        "black_level": int(black),
        "white_level": int(white),
        "voltage_swing": 1.0,
        "sensor": "pidng fixture " + stem,
        "source": f"scripts/pidng_fixtures.py (PiDNG {pidng_version()}): {note}",
    }
    with open(os.path.join(OUT, stem + ".json"), "w") as f:
        json.dump(meta, f, indent=2)
        f.write("\n")


def pidng_version():
    try:
        from importlib.metadata import version

        return version("pidng")
    except Exception:  # pragma: no cover - metadata missing
        return getattr(pidng, "__version__", "4.x")


def rgbw():
    w, h, black, white = 64, 48, 4096, 65535
    data = mosaic(w, h, black, white, [300, 900, 1500, 0])  # R G / W B
    t = tags(
        w, h, 16, [0, 1, 6, 2], black, white,
        # R, G, B, W: the order of the planes the reader infers without CFAPlaneColor
        [[3, 5], [1, 1], [1, 2], [1, 1]],
        CalibrationIlluminant.Standard_Light_A,
    )
    t.set(Tag.Make, "PiDNG")
    t.set(Tag.Model, "RGBW fixture")
    write("rgbw_pidng", t, data, "RG/WB", black, white, "RGBW without CFAPlaneColor")


def bayer():
    w, h, black, white = 32, 24, 512, 16383
    data = mosaic(w, h, black, white, [0, 200, 200, 400])  # R G / G B
    t = tags(
        w, h, 16, [0, 1, 1, 2], black, white,
        [[1, 2], [1, 1], [7, 10]],
        CalibrationIlluminant.D65,
    )
    t.set(Tag.Make, "SONY")
    t.set(Tag.Model, "ILCE-9")
    t.set(Tag.UniqueCameraModel, "Sony ILCE-9")
    write("bayer_sony", t, data, "RG/GB", black, white, "Bayer with Make, Model, UniqueCameraModel")


def sony_macbeth():
    """A simulated frame of the Sony ILCE-9 (the catalogue sensor) as the camera would name it."""
    l3 = os.environ.get("L3", os.path.join(ROOT, "target", "debug", "l3"))
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run(
            [l3, "simulate", "--sensor", "bayer-sony-ilce-9", "--scene", "macbeth",
             "--illuminant", "D65", "--seed", "1", "--out", tmp],
            check=True, stdout=subprocess.DEVNULL,
        )
        with open(os.path.join(tmp, "mosaic.json")) as f:
            meta = json.load(f)
        w, h = meta["width"], meta["height"]
        codes = np.fromfile(os.path.join(tmp, "mosaic.raw"), dtype="<u2").reshape(h, w)
    black, white = 512, 16383
    span = meta["white_level"] - meta["black_level"]
    v = black + (codes.astype(np.float64) - meta["black_level"]) * (white - black) / span
    data = np.clip(np.round(v), black, white).astype(np.uint16)
    # AsShotNeutral: the camera's response to the white patch (19: row 4, column 1 of 32-px
    # patches), the middle half of it, per CFA colour, relative to green
    p = w // 6
    patch = data[3 * p + p // 4: 4 * p - p // 4, p // 4: p - p // 4].astype(np.float64) - black
    y0, x0 = 3 * p + p // 4, p // 4
    yy, xx = np.mgrid[0:patch.shape[0], 0:patch.shape[1]]
    site = ((yy + y0) % 2) * 2 + (xx + x0) % 2  # 0 R, 1 G, 2 G, 3 B
    r, g, b = patch[site == 0].mean(), patch[(site == 1) | (site == 2)].mean(), patch[site == 3].mean()
    neutral = [[int(round(r / g * 10000)), 10000], [1, 1], [int(round(b / g * 10000)), 10000]]
    t = tags(w, h, 16, [0, 1, 1, 2], black, white, neutral, CalibrationIlluminant.D65)
    t.set(Tag.Make, "SONY")
    t.set(Tag.Model, "ILCE-9")
    t.set(Tag.UniqueCameraModel, "Sony ILCE-9")
    write("sony_macbeth", t, data, "RG/GB", black, white,
          "l3 simulate --sensor bayer-sony-ilce-9 --scene macbeth --illuminant D65 --seed 1, in 14 bits")


def main():
    os.makedirs(OUT, exist_ok=True)
    rgbw()
    bayer()
    sony_macbeth()
    print(f"wrote rgbw_pidng, bayer_sony and sony_macbeth (DNG, raw, json) in {OUT} with PiDNG {pidng_version()}")


if __name__ == "__main__":
    main()
