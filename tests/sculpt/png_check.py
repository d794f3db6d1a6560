#!/usr/bin/env python3
"""Checks the screenshots of tests/sculpt/carve.json (standard library only: zlib + struct).

png_check.py DIR CURSOR_FX CURSOR_FY
  DIR/before.png   the surface, overlay hidden: a plausible share of lit (non-background) pixels
  DIR/probe.png    the same view with the overlay: the probe is drawn near the cursor
  DIR/carved.png   after carving at the cursor (overlay hidden): pixels changed around the cursor
  DIR/undone.png   after Ctrl+Z (overlay hidden): exactly before.png
Exit 0 when every check holds, 1 otherwise (each failure printed).
"""
import struct
import sys
import zlib


def read_png(path):
    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError(f"{path}: not a PNG")
    pos, idat, w = 8, b"", None
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            w, h, depth, ctype, _, _, interlace = struct.unpack(">IIBBBBB", body)
            if depth != 8 or ctype not in (2, 6) or interlace:
                raise ValueError(f"{path}: only 8-bit RGB/RGBA, non-interlaced")
            bpp = 3 if ctype == 2 else 4
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    raw = zlib.decompress(idat)
    stride = w * bpp
    rows, prev = [], bytearray(stride)
    for y in range(h):
        ft = raw[y * (stride + 1)]
        line = bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b = prev[i]
            c = prev[i - bpp] if i >= bpp else 0
            if ft == 1:
                line[i] = (line[i] + a) & 255
            elif ft == 2:
                line[i] = (line[i] + b) & 255
            elif ft == 3:
                line[i] = (line[i] + (a + b) // 2) & 255
            elif ft == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append(bytes(line))
        prev = line
    px = [tuple(r[x * bpp:x * bpp + 3]) for r in rows for x in range(w)]
    return w, h, px


def main():
    d, fx, fy = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
    imgs = {n: read_png(f"{d}/{n}.png") for n in ("before", "probe", "carved", "undone")}
    w, h, before = imgs["before"]
    cx, cy = fx * (w - 1), fy * (h - 1)
    fails = []
    for n, (wi, hi, _) in imgs.items():
        if (wi, hi) != (w, h):
            fails.append(f"{n}.png is {wi}x{hi}, before.png {w}x{h}")
    if fails:
        print("\n".join(fails))
        return 1
    bg = before[0]
    lit = sum(p != bg for p in before) / len(before)
    print(f"before: {lit:.1%} of the pixels show the surface")
    if not 0.03 <= lit <= 0.9:
        fails.append(f"before.png: {lit:.1%} lit pixels, expected 3 % to 90 %")

    def changed(a, b):
        return [(i % w, i // w) for i, (p, q) in enumerate(zip(a, b)) if p != q]

    def near(pts, r):
        return sum((x - cx) ** 2 + (y - cy) ** 2 <= r * r for x, y in pts)

    r = 0.08 * h
    probe = changed(before, imgs["probe"][2])
    print(f"probe: {len(probe)} pixels differ from before, {near(probe, r)} within {r:.0f} px of the cursor")
    if near(probe, r) < 20:
        fails.append("probe.png: the probe is not drawn near the cursor")
    carved = changed(before, imgs["carved"][2])
    print(f"carved: {len(carved)} pixels differ from before, {near(carved, r)} within {r:.0f} px of the cursor")
    if near(carved, r) < 20:
        fails.append("carved.png: carving did not change the pixels around the cursor")
    if len(carved) and near(carved, 2 * r) < 0.8 * len(carved):
        fails.append("carved.png: most changed pixels are far from the cursor")
    undone = changed(before, imgs["undone"][2])
    print(f"undone: {len(undone)} pixels differ from before")
    if undone:
        fails.append(f"undone.png: {len(undone)} pixels differ from before.png (undo must restore the picture exactly)")
    for f in fails:
        print("FAIL", f)
    return 1 if fails else 0


if __name__ == "__main__":
    sys.exit(main())
