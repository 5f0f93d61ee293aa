#!/usr/bin/env python3
"""Writes the DNG fixtures under tests/fixtures/dng/ with a third-party writer (PiDNG), each
beside its raw twin: the same mosaic as little-endian u16 `.raw` plus the JSON sidecar that
`l3` reads, with the same levels. tests/io/dng_fixtures.rs checks that every DNG decodes and
renders exactly as its twin.

    python3.9 -m pip install 'pidng>=4,<5' numpy
    python3.9 scripts/make_dng_fixtures.py          # rewrites tests/fixtures/dng/

PiDNG 4.0.9's lossless JPEG extension (ljpegCompress) only runs on Python 3.9 or older: on
3.10+ it fails with "PY_SSIZE_T_CLEAN macro must be defined for '#' formats".

Twelve small (32x24) DNGs: Bayer (RGGB) and RGBW (CFAPattern 0 1 6 2, CFAPlaneColor 0 1 2 6),
uncompressed (packed 10 and 12 bits, 16 bits) and lossless JPEG (PiDNG's LJ92, predictor 6),
at 10, 12 and 16 bits. Some also exercise the tags the reader applies:
  - bayer_10_*: a LinearizationTable (10-bit codes to a 0-16383 curve), white level 16383
  - rgbw_12_*: ActiveArea (2 rows and 2 columns masked at the top left) and DefaultCrop
    (origin 1,1, size 26x18): the twin's CFA is R G / W B seen from (1, 1), "BW/GR"
  - rgbw_*: BlackLevel per CFA position (BlackLevelRepeatDim 2x2, four equal values)
  - all: AsShotNeutral, CalibrationIlluminant1 (A for RGBW, D65 for Bayer), UniqueCameraModel

Checked with exiftool 12.57 (Debian libimage-exiftool-perl), e.g.
`exiftool -s -CFAPattern -CFAPlaneColor -BlackLevel -WhiteLevel -Compression -BitsPerSample
-ActiveArea -DefaultCropOrigin -DefaultCropSize -AsShotNeutral -CalibrationIlluminant1
-UniqueCameraModel`, with no warning for any of the twelve files:

  rgbw_12_lj92.dng
    Compression                     : JPEG
    BitsPerSample                   : 12
    CFAPattern                      : [Red,Green][White,Blue]
    CFAPlaneColor                   : Red,Green,Blue,White
    BlackLevel                      : 256 256 256 256
    WhiteLevel                      : 4095
    ActiveArea                      : 2 2 24 32
    DefaultCropOrigin               : 1 1
    DefaultCropSize                 : 26 18
    AsShotNeutral                   : 0.6 1 0.5 1
    CalibrationIlluminant1          : Standard Light A
    UniqueCameraModel               : PiDNG fixture rgbw_12_lj92
  bayer_10_raw.dng
    Compression                     : Uncompressed
    BitsPerSample                   : 10
    CFAPattern                      : [Red,Green][Green,Blue]
    CFAPlaneColor                   : Red,Green,Blue
    BlackLevel                      : 446
    WhiteLevel                      : 16383
    AsShotNeutral                   : 0.5 1 0.7
    CalibrationIlluminant1          : D65
    UniqueCameraModel               : PiDNG fixture bayer_10_raw
(the full output of every file is written to tests/fixtures/dng/exiftool.txt when exiftool is
installed).
"""

import json
import os
import shutil
import subprocess
import sys

import numpy as np
from pidng.core import RAW2DNG, DNGTags, Tag
from pidng.defs import CalibrationIlluminant, DNGVersion, PhotometricInterpretation

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
OUT = os.path.join(ROOT, "tests", "fixtures", "dng")
W, H = 32, 24

CFAS = {
    # name: (pattern codes, plane colours, the crate's CFA string, AsShotNeutral)
    "bayer": ([0, 1, 1, 2], [0, 1, 2], ["RG", "GB"], [[1, 2], [1, 1], [7, 10]]),
    "rgbw": ([0, 1, 6, 2], [0, 1, 2, 6], ["RG", "WB"], [[3, 5], [1, 1], [1, 2], [1, 1]]),
}


def lj92_safe(stored, bits):
    """Whether PiDNG's LJ92 encoder writes `stored` as standard lossless JPEG. It encodes the
    frame as one component of twice the width and half the height with predictor 6, and
    computes each difference as `sample - predictor % 65535`, without wrapping it modulo
    65536: a predictor of 65535 becomes 0, and a difference of 32768 or more gets category 16
    with 16 extra bits, which T.81 (and LibRaw, and our reader) read as a difference of 32768
    with none. Only 16-bit frames can meet either case."""
    img = stored.reshape(stored.shape[0] // 2, stored.shape[1] * 2).astype(np.int64)
    px = np.zeros_like(img)
    px[0, 0] = 1 << (bits - 1)
    px[0, 1:] = img[0, :-1]
    px[1:, 0] = img[:-1, 0]
    px[1:, 1:] = img[:-1, 1:] + ((img[1:, :-1] - img[:-1, :-1]) >> 1)
    diff = img - np.fmod(px, 65535)  # C's %, which keeps the sign
    return bool(np.all(np.abs(diff) < 32768))


def mosaic(seed, bits, black, white):
    """A smooth scene with texture and a few clipped pixels, in [black, white]."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:H, 0:W]
    base = 0.5 + 0.35 * np.sin(x / 5.0) * np.cos(y / 4.0)
    base += 0.04 * rng.standard_normal((H, W))
    v = black + np.clip(base, 0.0, 1.05) * (white - black)
    # (16-bit frames stay below 65535: see lj92_safe)
    top = min((1 << bits) - 1, 65534)
    v = np.clip(np.round(v), 0, top).astype(np.uint16)
    v[0, 0] = top  # one saturated pixel
    return v


def write_twin(stem, data, cfa, black, white):
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
        "source": "scripts/make_dng_fixtures.py (PiDNG); the mosaic the DNG decodes to",
    }
    with open(os.path.join(OUT, stem + ".json"), "w") as f:
        json.dump(meta, f, indent=2)
        f.write("\n")


def make(kind, bits, compress, seed):
    codes, planes, rows, neutral = CFAS[kind]
    stem = f"{kind}_{bits}_{'lj92' if compress else 'raw'}"
    white = (1 << bits) - 1
    black = {10: 64, 12: 256, 16: 4096}[bits]
    stored = mosaic(seed, bits, black, white)
    # the first seed from `seed` on whose frame PiDNG's LJ92 is standard (see lj92_safe)
    while compress and not lj92_safe(stored, bits):
        seed += 1000
        stored = mosaic(seed, bits, black, white)

    t = DNGTags()
    t.set(Tag.ImageWidth, W)
    t.set(Tag.ImageLength, H)
    t.set(Tag.TileWidth, W)
    t.set(Tag.TileLength, H)
    t.set(Tag.PhotometricInterpretation, PhotometricInterpretation.Color_Filter_Array)
    t.set(Tag.SamplesPerPixel, 1)
    t.set(Tag.BitsPerSample, bits)
    t.set(Tag.CFARepeatPatternDim, [2, 2])
    t.set(Tag.CFAPattern, codes)
    t.set(Tag.CFAPlaneColor, planes)
    t.set(Tag.DNGVersion, DNGVersion.V1_4)
    t.set(Tag.DNGBackwardVersion, DNGVersion.V1_1)
    t.set(Tag.UniqueCameraModel, f"PiDNG fixture {stem}")
    t.set(Tag.AsShotNeutral, neutral)
    t.set(
        Tag.CalibrationIlluminant1,
        CalibrationIlluminant.Standard_Light_A if kind == "rgbw" else CalibrationIlluminant.D65,
    )

    # what the reader must produce from the stored mosaic
    out = stored.astype(np.int64)
    out_white = white
    cfa_rows = rows
    if kind == "bayer" and bits == 10:
        # 10-bit codes through a curve to 0..16383
        table = np.round(16383 * (np.arange(1024) / 1023.0) ** 1.3).astype(np.uint16)
        t.set(Tag.LinearizationTable, [int(v) for v in table])
        out = table[stored].astype(np.int64)
        black = int(table[black])
        out_white = 16383
    if kind == "rgbw":
        t.set(Tag.BlackLevelRepeatDim, [2, 2])
        t.set(Tag.BlackLevel, [black] * 4)
    else:
        t.set(Tag.BlackLevel, black)
    t.set(Tag.WhiteLevel, out_white)
    if kind == "rgbw" and bits == 12:
        # ActiveArea: top, left, bottom, right; the CFA pattern starts at its corner
        t.set(Tag.ActiveArea, [2, 2, H, W])
        t.set(Tag.DefaultCropOrigin, [1, 1])
        t.set(Tag.DefaultCropSize, [26, 18])
        out = out[2:, 2:][1 : 1 + 18, 1 : 1 + 26]
        # seen from (1, 1) of the active area, R G / W B becomes B W / G R
        cfa_rows = [rows[1][1] + rows[1][0], rows[0][1] + rows[0][0]]

    if compress and (H % 2):
        sys.exit("LJ92 through PiDNG needs an even height")
    if compress and not lj92_safe(stored, bits):
        sys.exit(f"{stem}: PiDNG would write non-standard lossless JPEG for this frame")
    r = RAW2DNG()
    r.options(t, path=OUT, compress=compress)
    r.convert(stored, filename=stem)
    write_twin(stem, out.astype(np.uint16), "/".join(cfa_rows), black, out_white)
    return stem


def main():
    os.makedirs(OUT, exist_ok=True)
    stems = []
    seed = 1
    for kind in ("bayer", "rgbw"):
        for bits in (10, 12, 16):
            for compress in (False, True):
                stems.append(make(kind, bits, compress, seed))
                seed += 1
    print(f"wrote {len(stems)} DNGs and their raw twins in {OUT}")
    if shutil.which("exiftool"):
        files = [os.path.join(OUT, s + ".dng") for s in stems]
        report = subprocess.run(
            ["exiftool", "-s", "-G1", "-a"] + files, capture_output=True, text=True, check=True
        ).stdout
        # exiftool's version and the file system dates change with every run: drop them
        keep = [
            line
            for line in report.splitlines()
            if not any(k in line for k in ("FileModifyDate", "FileAccessDate", "FileInodeChangeDate", "FilePermissions", "Directory", "ExifToolVersion"))
        ]
        with open(os.path.join(OUT, "exiftool.txt"), "w") as f:
            f.write("\n".join(keep) + "\n")
        warnings = [line for line in keep if "Warning" in line or "Error" in line]
        print(f"exiftool read all {len(files)} files; {len(warnings)} warnings")
        for w in warnings:
            print("  " + w)


if __name__ == "__main__":
    main()
