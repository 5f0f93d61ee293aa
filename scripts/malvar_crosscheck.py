#!/usr/bin/env python3
"""Cross-check l3's Malvar-He-Cutler demosaic against colour-demosaicing's.

    pip install colour-demosaicing tifffile
    scripts/malvar_crosscheck.py [path/to/l3]   # default: target/release/l3

For each Bayer phase (RGGB, GRBG, GBRG, BGGR) it writes a natural-ish 16-bit mosaic (smooth
colour gradients, edges and noise) as a binary PGM, demosaics it with
`l3 demosaic --method malvar` (32-bit float TIFF out) and with
`colour_demosaicing.demosaicing_CFA_Bayer_Malvar2004`, and asserts that the largest relative
difference, away from a 2-pixel border, is at most 1e-4. The border is left out because
colour-demosaicing extends the frame by reflection about the edge pixel's outer side
(scipy's 'reflect': d c b a | a b c d) while l3 mirrors about the edge pixel (d c b | a b c d).
"""

import os
import subprocess
import sys
import tempfile

import numpy as np
import tifffile
from colour_demosaicing import demosaicing_CFA_Bayer_Malvar2004

L3 = sys.argv[1] if len(sys.argv) > 1 else "target/release/l3"
H, W = 96, 128
TOL = 1e-4


def scene(rng):
    """A natural-ish RGB scene in [0, 1]: gradients, a disc, a slanted edge, noise."""
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    r = 0.3 + 0.4 * x / W + 0.1 * np.sin(y / 7.0)
    g = 0.5 + 0.3 * np.cos(x / 11.0) * np.sin(y / 13.0)
    b = 0.2 + 0.5 * y / H
    disc = (x - 80) ** 2 + (y - 40) ** 2 < 20**2
    edge = x > 30 + 0.2 * y
    rgb = np.stack([r, g, b], axis=-1)
    rgb[disc] = [0.9, 0.2, 0.1]
    rgb[edge & ~disc] *= 0.5
    return np.clip(rgb + 0.02 * rng.standard_normal(rgb.shape), 0.0, 1.0)


def mosaic(rgb, pattern):
    """The Bayer mosaic of `rgb` for `pattern` (e.g. RGGB: row 0 R G, row 1 G B)."""
    idx = {"R": 0, "G": 1, "B": 2}
    out = np.zeros((H, W))
    for k, ch in enumerate(pattern):
        out[k // 2 :: 2, k % 2 :: 2] = rgb[k // 2 :: 2, k % 2 :: 2, idx[ch]]
    return np.round(out * 65535).astype(np.uint16)


def write_pgm(path, img):
    with open(path, "wb") as f:
        f.write(b"P5\n%d %d\n65535\n" % (img.shape[1], img.shape[0]))
        f.write(img.astype(">u2").tobytes())


def main():
    rng = np.random.default_rng(7)
    worst = 0.0
    with tempfile.TemporaryDirectory() as tmp:
        for pattern in ["RGGB", "GRBG", "GBRG", "BGGR"]:
            cfa = pattern[:2] + "/" + pattern[2:]
            m = mosaic(scene(rng), pattern)
            pgm = os.path.join(tmp, pattern + ".pgm")
            tif = os.path.join(tmp, pattern + ".tiff")
            write_pgm(pgm, m)
            subprocess.run(
                [L3, "demosaic", "--in", pgm, "--cfa", cfa, "--method", "malvar", "--out", tif],
                check=True,
                stdout=subprocess.DEVNULL,
            )
            ours = tifffile.imread(tif).astype(np.float64)
            theirs = demosaicing_CFA_Bayer_Malvar2004(m.astype(np.float64), pattern)
            inner = (slice(2, -2), slice(2, -2))
            diff = np.abs(ours[inner] - theirs[inner])
            rel = diff / np.maximum(np.abs(theirs[inner]), 1.0)
            edge = np.abs(ours - theirs).max()
            print(
                f"{pattern}: max relative difference {rel.max():.2e} away from a 2-px border "
                f"(max absolute {diff.max():.3g} DN; {edge:.3g} DN with the border)"
            )
            worst = max(worst, rel.max())
    print(f"worst over the four phases: {worst:.2e} (tolerance {TOL:.0e})")
    if worst > TOL:
        sys.exit(1)


if __name__ == "__main__":
    main()
