#!/usr/bin/env bash
# Cross-checks `l3 eval --scielab` against ISETCam's `scielab` under GNU Octave.
#
#   ISETCAM_DIR=/path/to/isetcam scripts/scielab_crosscheck.sh [WORKDIR]
#
# Needs: octave and octave-image (Debian: apt-get install octave octave-image; ISETCam's
# scApplyFilters calls padarray), python3 with numpy, and a checkout of
# ISETCam (github.com/ISET/isetcam; only its metrics/scielab, metrics/cielab,
# color/transforms and utility functions are called) outside this repository. L3_BIN picks
# the l3 binary (default: `cargo build` then target/debug/l3, or $CARGO_TARGET_DIR/debug/l3).
#
# It writes four image pairs (XYZ, D65, white Y = 1; 129 × 97 pixels, odd so that ISETCam
# trims nothing), scores each with ISETCam's scielab (imageFormat 'xyz2', sampPerDeg 41,
# filterSize 41) and with l3 (--samples-per-degree 41) for both filter sets and both ΔE
# formulas, and prints how far the per-pixel ΔE maps and their means are apart.
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
: "${ISETCAM_DIR:?set ISETCAM_DIR to a checkout of ISETCam}"
work="${1:-$(mktemp -d)}"
mkdir -p "$work"
if [[ -z "${L3_BIN:-}" ]]; then
  (cd "$here" && cargo build --quiet --bin l3)
  L3_BIN="${CARGO_TARGET_DIR:-$here/target}/debug/l3"
fi
command -v octave >/dev/null || { echo "octave is not installed" >&2; exit 1; }
export L3_BIN ISETCAM_DIR WORK="$work"
python3 - <<'PY'
import os, struct, subprocess, json
import numpy as np

work, l3, isetcam = os.environ["WORK"], os.environ["L3_BIN"], os.environ["ISETCAM_DIR"]
W, H, SPD = 129, 97, 41
WHITE = np.array([0.95047, 1.0, 1.08883])
M = np.array([[278.7336, 721.8031, -106.5520],
              [-448.7736, 289.8056, 77.1569],
              [85.9513, -589.9859, 501.1089]]) / 1000.0
rng = np.random.default_rng(2026)

def write_tiff_rgb32f(path, img):
    h, w, _ = img.shape
    data = np.ascontiguousarray(img, dtype="<f4").tobytes()
    entries = []  # (tag, type, count, value-or-offset)
    extra = b""
    base = 8 + 2 + 11 * 12 + 4
    def shorts3(v):
        nonlocal extra
        off = base + len(extra)
        extra += struct.pack("<3H", v, v, v) + b"\0\0"
        return off
    bps, fmt = shorts3(32), shorts3(3)
    data_off = base + len(extra)
    entries = [(256, 4, 1, w), (257, 4, 1, h), (258, 3, 3, bps), (259, 3, 1, 1),
               (262, 3, 1, 2), (273, 4, 1, data_off), (277, 3, 1, 3), (278, 4, 1, h),
               (279, 4, 1, len(data)), (284, 3, 1, 1), (339, 3, 3, fmt)]
    ifd = struct.pack("<H", len(entries))
    for tag, typ, count, val in entries:
        packed = struct.pack("<H", val) + b"\0\0" if (typ == 3 and count == 1) else struct.pack("<I", val)
        ifd += struct.pack("<HHI", tag, typ, count) + packed
    ifd += struct.pack("<I", 0)
    with open(path, "wb") as f:
        f.write(b"II" + struct.pack("<HI", 42, 8) + ifd + extra + data)

def read_tiff_gray32f(path):
    b = open(path, "rb").read()
    assert b[:2] == b"II", "little-endian TIFF expected"
    (off,) = struct.unpack_from("<I", b, 4)
    (n,) = struct.unpack_from("<H", b, off)
    tags = {}
    for i in range(n):
        tag, typ, count = struct.unpack_from("<HHI", b, off + 2 + 12 * i)
        size = {3: 2, 4: 4}.get(typ, 1) * count
        pos = off + 2 + 12 * i + 8
        if size > 4:
            (pos,) = struct.unpack_from("<I", b, pos)
        code = {3: "H", 4: "I"}.get(typ, "B")
        tags[tag] = struct.unpack_from("<%d%s" % (count, code), b, pos)
    assert tags.get(259, (1,))[0] == 1, "uncompressed TIFF expected"
    w, h = tags[256][0], tags[257][0]
    raw = b"".join(b[o:o + c] for o, c in zip(tags[273], tags[279]))
    return np.frombuffer(raw, dtype="<f4").reshape(h, w).astype(np.float64)

def smooth_field(scale):
    y, x = np.mgrid[0:H, 0:W] / scale
    return np.stack([0.35 + 0.25 * np.sin(x + 0.7 * c) * np.cos(0.8 * y - c) for c in range(3)], -1)

def to_xyz(rgbish):
    # a plausible XYZ from an RGB-like field: linear sRGB primaries
    srgb2xyz = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])
    return np.clip(rgbish, 0.01, 1.0) @ srgb2xyz.T

def patches():
    cols = rng.uniform(0.05, 0.9, size=(6, 8, 3))
    yy = (np.arange(H) * 6 // H)[:, None]
    xx = (np.arange(W) * 8 // W)[None, :]
    return cols[yy, xx]

def discs():
    img = np.full((H, W, 3), 0.3)
    y, x = np.mgrid[0:H, 0:W]
    for _ in range(60):
        cy, cx, r = rng.uniform(0, H), rng.uniform(0, W), rng.uniform(3, 18)
        img[(y - cy) ** 2 + (x - cx) ** 2 < r * r] = rng.uniform(0.03, 0.95, 3)
    return img

def box3(img):
    p = np.pad(img, ((1, 1), (1, 1), (0, 0)), mode="edge")
    return sum(p[dy:dy + H, dx:dx + W] for dy in range(3) for dx in range(3)) / 9.0

pairs = {}
a = to_xyz(smooth_field(9.0))
pairs["smooth+lum-noise"] = (a, np.clip(a * (1 + 0.06 * rng.standard_normal((H, W, 1))), 0, None))
a = to_xyz(patches())
opp_noise = rng.standard_normal((H, W, 3)) * np.array([0.0, 0.02, 0.02])
pairs["patches+chroma-noise"] = (a, np.clip(a + opp_noise @ np.linalg.inv(M).T + 0.01 * np.array([0.02, 0, -0.03]), 0, None))
d = discs()
pairs["discs+blur+shift"] = (to_xyz(d), to_xyz(np.roll(box3(d), 1, axis=1)))
u1, u2 = np.array([0.3, 0.32, 0.28]), np.array([0.33, 0.31, 0.35])
pairs["uniform"] = (np.broadcast_to(u1, (H, W, 3)).copy(), np.broadcast_to(u2, (H, W, 3)).copy())

names = list(pairs)
for i, name in enumerate(names):
    for tag, img in zip(("ideal", "rendered"), pairs[name]):
        img32 = img.astype(np.float32)
        write_tiff_rgb32f(f"{work}/p{i}_{tag}.tiff", img32)
        img32.tofile(f"{work}/p{i}_{tag}.f32")

# (ISETCam filters, l3 filters, ΔE). 'paper-sigma' is ISETCam's own filter code (sumGauss) fed
# the paper's spreads read as the paper defines them, exp(-r²/σ²), i.e. a half-width at half
# maximum of σ·√ln 2, where ISETCam's 'original' takes the printed σ as that half-width.
configs = [("distribution", "distribution", "2000"), ("distribution", "distribution", "1976"),
           ("original", "paper", "2000"), ("original", "paper", "1976"),
           ("paper-sigma", "paper", "2000")]
driver = f"{work}/run_isetcam.m"
with open(driver, "w") as f:
    f.write(f"pkg load image\naddpath(genpath('{isetcam}'));\nW={W}; H={H};\n")
    f.write(f"wp = [{WHITE[0]} {WHITE[1]} {WHITE[2]}];\n")
    for ci, (iset_v, _, de) in enumerate(configs):
        for i in range(len(names)):
            f.write(f"""
fid = fopen('{work}/p{i}_ideal.f32'); a = fread(fid, inf, 'single=>double'); fclose(fid);
fid = fopen('{work}/p{i}_rendered.f32'); b = fread(fid, inf, 'single=>double'); fclose(fid);
a = permute(reshape(a, [3 W H]), [3 2 1]); b = permute(reshape(b, [3 W H]), [3 2 1]);
params = struct('sampPerDeg', {SPD}, 'filterSize', {SPD}, 'filters', [], 'filterversion', '{iset_v}', ...
                'deltaEversion', '{de}', 'imageFormat', 'xyz2');
if strcmp(params.filterversion, 'paper-sigma')
  params.filterversion = 'original';
  [x1, x2, x3] = scGaussianParameters({SPD}, params);
  k = sqrt(log(2)); x1([1 3 5]) = x1([1 3 5]) * k; x2([1 3]) = x2([1 3]) * k; x3([1 3]) = x3([1 3]) * k;
  params.filters = {{sumGauss([{SPD} x1], 2), sumGauss([{SPD} x2], 2), sumGauss([{SPD} x3], 2)}};
end
dE = scielab(a, b, wp, params);
fid = fopen('{work}/iset_c{ci}_p{i}.f64', 'w'); fwrite(fid, size(dE), 'double'); fwrite(fid, dE.', 'double'); fclose(fid);
""")
subprocess.run(["octave", "--no-gui", "--quiet", "--eval", f"run('{driver}')"], check=True)

print(f"ISETCam scielab vs l3 eval --scielab: {W}x{H} px, {SPD} samples/degree, 41-tap filters")
print("| pair | ISETCam filters | l3 filters | ΔE | l3 border | mean ISETCam | mean l3 | |Δmean| | per-pixel |diff| mean | max | interior max |")
print("|---|---|---|---|---|---|---|---|---|---|---|")
summary = []
for ci, (iset_v, ours_v, de) in enumerate(configs):
    for border in ("periodic", "symmetric"):
        for i, name in enumerate(names):
            out, mp = f"{work}/l3_c{ci}_{border}_p{i}.json", f"{work}/l3_c{ci}_{border}_p{i}.tiff"
            subprocess.run([l3, "eval", "--scielab", f"{work}/p{i}_ideal.tiff", f"{work}/p{i}_rendered.tiff",
                            "--samples-per-degree", str(SPD), "--delta-e", de, "--scielab-filters", ours_v,
                            "--border", border, "--map", mp, "--out", out],
                           check=True, stdout=subprocess.DEVNULL)
            ours = read_tiff_gray32f(mp)
            raw = np.fromfile(f"{work}/iset_c{ci}_p{i}.f64", dtype="<f8")
            r, c = int(raw[0]), int(raw[1])
            iset = raw[2:].reshape(r, c)
            assert (r, c) == ours.shape, ((r, c), ours.shape)
            # ISETCam's FFT convolution (fftshift, multiply, ifftshift on odd sizes) returns the
            # blurred images moved up and left by one pixel, wrapping round: align ours with it.
            d = np.abs(np.roll(ours, (-1, -1), axis=(0, 1)) - iset)
            m = 21  # one filter radius in from every edge
            print(f"| {name} | {iset_v} | {ours_v} | {de} | {border} | {iset.mean():.4f} | {ours.mean():.4f} | "
                  f"{abs(iset.mean() - ours.mean()):.2e} | {d.mean():.2e} | {d.max():.2e} | {d[m:-m, m:-m].max():.2e} |")
            summary.append(dict(pair=name, isetcam=iset_v, l3=ours_v, delta_e=de, border=border,
                                mean_isetcam=iset.mean(), mean_l3=ours.mean(),
                                pixel_diff_mean=d.mean(), pixel_diff_max=d.max()))
json.dump(summary, open(f"{work}/crosscheck.json", "w"), indent=1)
print(f"wrote {work}/crosscheck.json")
PY
