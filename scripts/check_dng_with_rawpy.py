#!/usr/bin/env python3
"""Cross-checks the DNG reader against LibRaw (through rawpy) on the Bayer fixtures.

    pip install rawpy numpy
    python3 scripts/check_dng_with_rawpy.py [tests/fixtures/dng]

For every bayer_*.dng under the folder, LibRaw's raw values (the visible area), black and
white levels and CFA are compared with the file's raw twin (bayer_*.raw + .json), which is
what `l3`'s reader gives for the DNG: tests/io/dng_fixtures.rs asserts that the decoded DNG
equals its twin pixel for pixel. LibRaw does not read RGBW CFAs (colour code 6), so only the
Bayer files are compared. Exits non-zero on any difference.
"""

import json
import os
import sys

import numpy as np
import rawpy

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")


def main():
    folder = sys.argv[1] if len(sys.argv) > 1 else os.path.join(ROOT, "tests", "fixtures", "dng")
    files = sorted(f for f in os.listdir(folder) if f.startswith("bayer_") and f.endswith(".dng"))
    if not files:
        sys.exit(f"no bayer_*.dng in {folder}")
    failures = 0
    for name in files:
        stem = os.path.join(folder, name[:-4])
        with open(stem + ".json") as f:
            meta = json.load(f)
        twin = np.fromfile(stem + ".raw", dtype="<u2").reshape(meta["height"], meta["width"])
        with rawpy.imread(os.path.join(folder, name)) as raw:
            libraw = raw.raw_image_visible.copy()
            letters = raw.color_desc.decode()
            cfa = "/".join(
                "".join(letters[raw.raw_pattern[r, c]] for c in range(raw.raw_pattern.shape[1]))
                for r in range(raw.raw_pattern.shape[0])
            )
            blacks = list(raw.black_level_per_channel)
            white = raw.white_level
        problems = []
        if libraw.shape != twin.shape:
            problems.append(f"size {libraw.shape} vs {twin.shape}")
        else:
            diff = np.abs(libraw.astype(np.int64) - twin.astype(np.int64))
            if diff.max() > 0:
                problems.append(f"{int((diff > 0).sum())} pixels differ, by up to {int(diff.max())}")
        # LibRaw names the second green G too (color_desc RGBG)
        if cfa != meta["cfa"]:
            problems.append(f"CFA {cfa} vs {meta['cfa']}")
        if any(b != meta["black_level"] for b in blacks):
            problems.append(f"black {blacks} vs {meta['black_level']}")
        if white != meta["white_level"]:
            problems.append(f"white {white} vs {meta['white_level']}")
        status = "identical" if not problems else "DIFFERENT: " + "; ".join(problems)
        print(
            f"{name}: LibRaw {libraw.shape[1]}x{libraw.shape[0]} {cfa} black {blacks[0]} "
            f"white {white}, {libraw.size} raw values: {status}"
        )
        failures += bool(problems)
    print(f"{len(files) - failures} of {len(files)} Bayer DNGs read identically by LibRaw {rawpy.libraw_version}")
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
