#!/usr/bin/env python3
"""Writes a full-size DNG laid out as Adobe's DNG Converter lays out a camera's raw file, for
timing how fast l3 reads one (docs/performance.md#reading-a-dng): an 8-bit preview in IFD0,
the raw CFA image in a SubIFD, 14-bit RGGB in 256 x 256 lossless-JPEG tiles of two
interleaved components (predictor 1, a Huffman table per component, optimal code lengths),
black 512, white 16383, a default crop. Every tile is the same textured, noisy 256 x 256
patch, encoded once.

    python3 -m pip install numpy
    python3 scripts/big_dng.py out/sony_ilce9_24mp.dng 6048 4024 "Sony ILCE-9"
    python3 scripts/big_dng.py out/fuji_gfx100_102mp.dng 11664 8752 "Fujifilm GFX 100"
"""
import heapq
import struct
import sys

import numpy as np

BYTE, ASCII, SHORT, LONG, RATIONAL = 1, 2, 3, 4, 5
TILE = 256


def code_lengths(freq):
    """Huffman code lengths per symbol (those that occur), with one reserved symbol so that
    no code is all ones (T.81 K.2)."""
    syms = [(f, s) for s, f in enumerate(freq) if f > 0] + [(0.5, 99)]
    heap = [(f, k, [s]) for k, (f, s) in enumerate(syms)]
    heapq.heapify(heap)
    depth = {s: 0 for _, s in syms}
    while len(heap) > 1:
        f1, k, a = heapq.heappop(heap)
        f2, _, b = heapq.heappop(heap)
        for s in a + b:
            depth[s] += 1
        heapq.heappush(heap, (f1 + f2, k, a + b))
    if max(depth.values()) > 16:
        sys.exit("a code longer than 16 bits; use less skewed data")
    return depth


def canonical(depth):
    """The DHT counts, the symbols in code order, and each symbol's (code, length)."""
    counts, values, codes, code, prev = [0] * 16, [], {}, 0, 0
    for s, n in sorted(depth.items(), key=lambda kv: (kv[1], kv[0])):
        code <<= n - prev
        prev = n
        if s != 99:
            codes[s] = (code, n)
            values.append(s)
            counts[n - 1] += 1
        code += 1
    return counts, values, codes


def ljpeg(tile, precision):
    """A lossless JPEG of `tile` (rows of 2 x width interleaved samples as DNG stores a
    Bayer tile), predictor 1."""
    h, w2 = tile.shape
    x = tile.astype(np.int64).reshape(h, w2 // 2, 2)
    pred = np.empty_like(x)
    pred[:, 1:] = x[:, :-1]
    pred[1:, 0] = x[:-1, 0]
    pred[0, 0] = 1 << (precision - 1)
    d = x - pred
    ssss = np.where(d == 0, 0, np.floor(np.log2(np.maximum(np.abs(d), 1))).astype(np.int64) + 1)
    tables = [canonical(code_lengths(np.bincount(ssss[:, :, c].ravel(), minlength=17)))
              for c in range(2)]
    out = bytearray(b"\xff\xd8")
    seg = b"".join(bytes([c]) + bytes(t[0]) + bytes(t[1]) for c, t in enumerate(tables))
    out += b"\xff\xc4" + struct.pack(">H", len(seg) + 2) + seg
    seg = bytes([precision]) + struct.pack(">HH", h, w2 // 2) + bytes([2, 0, 0x11, 0, 1, 0x11, 0])
    out += b"\xff\xc3" + struct.pack(">H", len(seg) + 2) + seg
    seg = bytes([2, 0, 0x00, 1, 0x10, 1, 0, 0])
    out += b"\xff\xda" + struct.pack(">H", len(seg) + 2) + seg
    acc, nbits = 0, 0
    for s_row, d_row in zip(ssss.reshape(-1, 2).tolist(), d.reshape(-1, 2).tolist()):
        for c in range(2):
            s, v = s_row[c], d_row[c]
            code, n = tables[c][2][s]
            acc, nbits = (acc << n) | code, nbits + n
            if s:
                acc, nbits = (acc << s) | (v if v > 0 else v + (1 << s) - 1), nbits + s
            while nbits >= 8:
                nbits -= 8
                byte = (acc >> nbits) & 0xFF
                out += b"\xff\x00" if byte == 0xFF else bytes([byte])
            acc &= (1 << nbits) - 1
    if nbits:
        byte = ((acc << (8 - nbits)) | ((1 << (8 - nbits)) - 1)) & 0xFF
        out += b"\xff\x00" if byte == 0xFF else bytes([byte])
    return bytes(out + b"\xff\xd9")


class Tiff:
    """A little-endian TIFF built in memory: blobs, then IFDs that point at them."""

    def __init__(self):
        self.buf = bytearray(b"II\x2a\x00\x00\x00\x00\x00")

    def blob(self, data):
        if len(self.buf) % 2:
            self.buf.append(0)
        self.buf += data
        return len(self.buf) - len(data)

    def ifd(self, entries):
        packed = []
        for tag, typ, vals in sorted(entries):
            if typ == ASCII:
                data, count = vals.encode() + b"\0", len(vals) + 1
            elif typ == RATIONAL:
                data, count = struct.pack("<%dI" % (2 * len(vals)), *sum(vals, ())), len(vals)
            else:
                fmt = {BYTE: "B", SHORT: "H", LONG: "I"}[typ]
                data, count = struct.pack("<%d%s" % (len(vals), fmt), *vals), len(vals)
            field = struct.pack("<I", self.blob(data)) if len(data) > 4 else data.ljust(4, b"\0")
            packed.append(struct.pack("<HHI", tag, typ, count) + field)
        at = self.blob(struct.pack("<H", len(packed)) + b"".join(packed) + b"\0\0\0\0")
        return at


def main():
    if len(sys.argv) != 5:
        sys.exit(__doc__)
    path, w, h, camera = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:TILE, 0:TILE]
    cfa = np.array([[0.42, 0.88], [0.88, 0.63]])
    tile = 512 + (0.3 + 0.2 * xx / TILE) * cfa[yy % 2, xx % 2] * (16383 - 512)
    tile = np.clip(np.rint(tile + rng.normal(0, 8, tile.shape)), 0, 16383).astype(np.uint16)
    data = ljpeg(tile, 14)
    t = Tiff()
    n = -(-w // TILE) * -(-h // TILE)
    offsets = [t.blob(data) for _ in range(n)]
    make, _, model = camera.partition(" ")
    raw = t.ifd([
        (254, LONG, [0]), (256, LONG, [w]), (257, LONG, [h]), (258, SHORT, [14]),
        (259, SHORT, [7]), (262, SHORT, [32803]), (277, SHORT, [1]), (284, SHORT, [1]),
        (322, SHORT, [TILE]), (323, SHORT, [TILE]), (324, LONG, offsets),
        (325, LONG, [len(data)] * n), (33421, SHORT, [2, 2]), (33422, BYTE, [0, 1, 1, 2]),
        (50710, BYTE, [0, 1, 2]), (50711, SHORT, [1]), (50713, SHORT, [2, 2]),
        (50714, RATIONAL, [(512, 1)] * 4), (50717, LONG, [16383]), (50829, LONG, [0, 0, h, w]),
        (50719, RATIONAL, [(12, 1), (8, 1)]), (50720, RATIONAL, [(w - 24, 1), (h - 16, 1)]),
    ])
    preview = t.blob(bytes(256 * 171 * 3))
    ifd0 = t.ifd([
        (254, LONG, [1]), (256, LONG, [256]), (257, LONG, [171]), (258, SHORT, [8, 8, 8]),
        (259, SHORT, [1]), (262, SHORT, [2]), (273, LONG, [preview]), (277, SHORT, [3]),
        (278, LONG, [171]), (279, LONG, [256 * 171 * 3]), (330, LONG, [raw]),
        (271, ASCII, make), (272, ASCII, model), (50708, ASCII, camera),
        (50706, BYTE, [1, 4, 0, 0]), (50707, BYTE, [1, 1, 0, 0]),
        (50728, RATIONAL, [(470, 1000), (1, 1), (710, 1000)]),
    ])
    t.buf[4:8] = struct.pack("<I", ifd0)
    with open(path, "wb") as f:
        f.write(t.buf)
    print(f"{path}: {w} x {h} ({w * h / 1e6:.1f} MP), {len(t.buf) >> 20} MiB, {n} tiles")


if __name__ == "__main__":
    main()
