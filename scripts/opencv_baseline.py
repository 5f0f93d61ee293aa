#!/usr/bin/env python3
"""OpenCV's bilinear demosaic plus a 3×3 colour matrix on a 12 MP u16 Bayer frame: the
conventional reference the render speed is compared with (docs/performance.md).

Times, on all cores (OpenCV's default threading), the median of N runs of
  u16 Bayer mosaic → cv2.cvtColor(COLOR_BayerRG2RGB) (bilinear, u16)
  → cv2.transform (3×3, u16 with saturation) → 8-bit (cv2.convertScaleAbs)
(no gamma: the cheapest form of the conventional pipeline, so the comparison flatters OpenCV)
and prints JSON. Needs `pip install opencv-python-headless numpy`.

    python3 scripts/opencv_baseline.py [--width 4000] [--height 3000] [--runs 20]
"""
import argparse
import json
import statistics
import time

import cv2
import numpy as np


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", type=int, default=4000)
    ap.add_argument("--height", type=int, default=3000)
    ap.add_argument("--runs", type=int, default=20)
    args = ap.parse_args()

    rng = np.random.default_rng(7)
    mosaic = rng.integers(0, 4096, size=(args.height, args.width), dtype=np.uint16)
    matrix = np.array(
        [[1.9, -0.6, -0.3], [-0.3, 1.6, -0.3], [0.0, -0.7, 1.7]], dtype=np.float32
    )
    scale = 255.0 / 4095.0

    def once():
        rgb = cv2.cvtColor(mosaic, cv2.COLOR_BayerRG2RGB)
        lin = cv2.transform(rgb, matrix)
        return cv2.convertScaleAbs(lin, alpha=scale)

    for _ in range(3):
        once()
    demosaic, total = [], []
    for _ in range(args.runs):
        t0 = time.perf_counter()
        rgb = cv2.cvtColor(mosaic, cv2.COLOR_BayerRG2RGB)
        t1 = time.perf_counter()
        lin = cv2.transform(rgb, matrix)
        out = cv2.convertScaleAbs(lin, alpha=scale)
        t2 = time.perf_counter()
        assert out.shape == (args.height, args.width, 3)
        demosaic.append((t1 - t0) * 1e3)
        total.append((t2 - t0) * 1e3)
    mpix = args.width * args.height / 1e6
    med = statistics.median(total)
    print(
        json.dumps(
            {
                "opencv": cv2.__version__,
                "threads": cv2.getNumThreads(),
                "width": args.width,
                "height": args.height,
                "runs": args.runs,
                "demosaic_ms_median": round(statistics.median(demosaic), 2),
                "total_ms_median": round(med, 2),
                "total_ms_min": round(min(total), 2),
                "mpix_per_s": round(mpix / (med / 1e3), 1),
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
