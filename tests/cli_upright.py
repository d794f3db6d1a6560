#!/usr/bin/env python3
"""Pictures upright from the direction matrix, never from a file's name.

1. The shipped head (slice 0 is the top of the head; its header says so with a direction of
   -1 along z) and a copy whose voxels are reversed along z under an identity direction (the
   same physical head, the other way in the file, under another name) render the same
   picture, and `isotouch render` says "up: superior" for both.
2. That picture is the one VTK's own Medical examples show of this data set (its original
   identity header viewed with view-up -z, `--up -z`) mirrored left-right: the identity header
   is a reflection of the head, and a picture shows the physical volume, not its mirror.
3. The picture is upright: the top of the head (slice 0 on) is drawn above the jaw (the last
   slices).
Pictures are compared as decoded here (zlib and PNG row filters in plain Python).

Usage: cli_upright.py ISOTOUCH SOURCE_DIR OUT_DIR; exit 0 and "PASS cli_upright".
"""
import array, os, re, struct, subprocess, sys, zlib

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cli_checks import Checks  # noqa: E402

isotouch, src, out = (os.path.abspath(a) for a in sys.argv[1:4])
head_dir = os.path.join(src, "data", "ct-head-headsq")
os.makedirs(out, exist_ok=True)
check = Checks()


def read_png(path):
    """(width, height, rows of RGB bytes) of an 8-bit RGB PNG."""
    data = open(path, "rb").read()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", path
    pos, idat = 8, b""
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            w, h, depth, ctype = struct.unpack(">IIBB", body[:10])
            assert depth == 8 and ctype == 2, "8-bit RGB expected"
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    raw, stride, rows, prev = zlib.decompress(idat), 3 * w, [], bytearray(3 * w)
    for y in range(h):
        f, line = raw[y * (stride + 1)], bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - 3] if i >= 3 else 0
            b, c = prev[i], (prev[i - 3] if i >= 3 else 0)
            if f == 1: line[i] = (line[i] + a) & 255
            elif f == 2: line[i] = (line[i] + b) & 255
            elif f == 3: line[i] = (line[i] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append(line)
        prev = line
    return w, h, rows


def render(tag, mhd, *extra):
    """isotouch render of a scene on `mhd` at isovalue 1150 (bone): (printed text, picture)."""
    scene = os.path.join(out, tag + ".json")
    with open(scene, "w") as f:
        f.write('{"name": "%s", "volume": {"path": "%s"}, "isovalue": 1150, "inside": "above"}\n' % (tag, mhd))
    png = os.path.join(out, tag + ".png")
    r = subprocess.run([isotouch, "render", scene, "--out", png, "--cpu", "--width", "160", "--height", "160", *extra],
                       capture_output=True, text=True, timeout=300)
    check(r.returncode == 0, f"{tag}: render exits 0 ({r.stderr.strip()[-200:]})")
    return r.stdout + r.stderr, (read_png(png) if r.returncode == 0 else (0, 0, []))


def silhouette(picture):
    """The picture with every surface pixel white and the background (pixel (0, 0)'s colour) black."""
    bg = picture[2][0][0:3]
    return (picture[0], picture[1], [bytearray(b"".join(b"\0\0\0" if row[i:i + 3] == bg else b"\xff\xff\xff"
                                                         for i in range(0, len(row), 3))) for row in picture[2]])


def differing(a, b):
    return sum(1 for ra, rb in zip(a[2], b[2]) for i in range(0, len(ra), 3) if ra[i:i + 3] != rb[i:i + 3])


header = open(os.path.join(head_dir, "headsq_64x64x93_int16.mhd")).read()
raw_path = os.path.join(head_dir, "headsq_64x64x93_int16.raw")
check("TransformMatrix = 1 0 0 0 1 0 0 0 -1" in header, "the shipped head's header says z runs inferior")

# The same head stored the other way: slices reversed, identity direction, offset 0.
vox = array.array("h", open(raw_path, "rb").read())
slice_n = 64 * 64
flipped = array.array("h")
for z in reversed(range(93)):
    flipped.extend(vox[z * slice_n:(z + 1) * slice_n])
open(os.path.join(out, "flipped.raw"), "wb").write(flipped.tobytes())


def with_header(name, matrix, offset, data_file):
    text = re.sub(r"TransformMatrix = .*", "TransformMatrix = " + matrix, header)
    text = re.sub(r"Offset = .*", "Offset = " + offset, text)
    text = re.sub(r"AnatomicalOrientation = .*", "AnatomicalOrientation = RAI", text)
    text = re.sub(r"ElementDataFile = .*", "ElementDataFile = " + data_file, text)
    path = os.path.join(out, name)
    open(path, "w").write(text)
    return path


shipped_text, shipped = render("shipped", os.path.join(head_dir, "headsq_64x64x93_int16.mhd"))
flip_text, flip = render("flipped", with_header("flipped.mhd", "1 0 0 0 1 0 0 0 1", "0 0 0", "flipped.raw"))
for tag, text in (("shipped", shipped_text), ("flipped", flip_text)):
    check("render: up: superior" in text, f"{tag}: render says up: superior")
n = differing(shipped, flip)
check(shipped[2] and n <= 0.002 * 160 * 160, f"voxels and direction flipped together: the same picture ({n} pixels differ)")

vtk_text, vtk = render("vtk-view-up", with_header("identity.mhd", "1 0 0 0 1 0 0 0 1", "0 0 0", raw_path), "--up", "-z")
# The identity header is a reflection of the head (slices run inferior, yet it says superior):
# VTK's view of it is upright but mirrored left-right.
mirrored = (vtk[0], vtk[1], [bytearray(b"".join(bytes(r[i:i + 3]) for i in range(len(r) - 3, -3, -3))) for r in vtk[2]])
# Compared as silhouettes (surface or background): the light, fixed to the camera, is not mirrored.
n = differing(silhouette(shipped), silhouette(mirrored))
check(vtk[2] and n <= 0.002 * 160 * 160,
      f"the silhouette VTK's examples show (identity header, view-up -z), mirrored left-right: {n} pixels differ")
n = differing(silhouette(shipped), silhouette(vtk))
check(n > 0.01 * 160 * 160, f"... and not the same unmirrored ({n} pixels differ): no mirror image of the head is shown")


# Upright: slice 0 is the top of the head (VTK's data set; the vertex region), the last slices
# hold the jaw. A copy holding only slices 0-9 and one holding only slices 70-92 (the rest
# air), under the shipped header, drawn with the same camera (the scan's box: --frame-scan;
# the default frames each object): the first in the
# picture's upper part, the second below it.
def rows_with_surface(picture):
    bg = picture[2][0][0:3]
    return [y for y, row in enumerate(picture[2]) if any(row[i:i + 3] != bg for i in range(0, len(row), 3))]


def only_slices(tag, first, last):
    part = array.array("h", [0]) * len(vox)
    part[first * slice_n:(last + 1) * slice_n] = vox[first * slice_n:(last + 1) * slice_n]
    open(os.path.join(out, tag + ".raw"), "wb").write(part.tobytes())
    text = re.sub(r"ElementDataFile = .*", "ElementDataFile = " + tag + ".raw", header)
    path = os.path.join(out, tag + ".mhd")
    open(path, "w").write(text)
    return render(tag, path, "--frame-scan")[1]


t, b = rows_with_surface(only_slices("slices-0-9", 0, 9)), rows_with_surface(only_slices("slices-70-92", 70, 92))
check(t and b and max(t) < min(b),
      f"upright: slices 0-9 (top of the head) drawn in rows {min(t or [0])}-{max(t or [0])}, above slices 70-92 "
      f"(the jaw) in rows {min(b or [0])}-{max(b or [0])} of 160")

check.finish("cli_upright")
