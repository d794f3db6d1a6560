#!/usr/bin/env python3
"""isotouch-sculpt's slice views (axial, coronal, sagittal through the probe), checked on the
shipped head against its raw voxels read here (--slices-png writes each slice one pixel per
voxel, and slices.json).

1. Each slice is the patient plane through the HIP as radiologists show it, worked out here
   from the header (ElementSpacing, Offset, TransformMatrix): axial = a plane of constant
   physical z with the patient's left (+x LPS) to the right and posterior (+y) down; coronal =
   constant y, left to the right, inferior down; sagittal = constant x, posterior to the
   right, inferior down. Every pixel off the marks shows its voxel through the window
   (grey = 255 (v - (L - W/2)) / W, clamped; the default window is the volume's range,
   computed here), and the bone voxels of the axial slice show bright.
2. The contour pixels are exactly the voxels inside (v > isovalue) with a 4-neighbour in the
   plane outside, computed here from the raw voxels.
3. A press on the axial view at a voxel chosen here (in air) moves the probe there: the HIP
   printed in slices.json lies within a voxel of it, and the yellow HIP mark sits at its index.
4. With a device (a playback of a trace.csv written here) the slices go through its HIP.
5. A carve shows in the slices (against the edited volume saved as .mha), and its undo too,
   with the probe at rest in air.
6. The head stored the other way (slices reversed along z, identity direction: the same
   physical volume) gives the same three slice pictures and the same window picture.
7. A labelled scene (scenes/tooth-labels.json): judged by its NIfTI label map read here, every
   pixel of a material off the marks shows that material's colour from the scene file,
   either half over its voxel's grey (the fill) or opaque (its boundary), a pixel of no
   material grey or the isocontour's colour; every material shows both ways in some plane.

Usage: cli_slices.py ISOTOUCH_SCULPT SOURCE_DIR OUT_DIR; exit 0 and "PASS cli_slices" (77: no xvfb-run).
"""
import array, gzip, json, math, os, re, shutil, struct, subprocess, sys

here = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, here)
sys.path.insert(0, os.path.join(here, "sculpt"))
from cli_checks import Checks  # noqa: E402
from png_check import read_png  # noqa: E402

sculpt, src, out = (os.path.abspath(a) for a in sys.argv[1:4])
os.makedirs(out, exist_ok=True)
check = Checks()
if shutil.which("xvfb-run") is None:
    print("SKIP: no xvfb-run")
    sys.exit(77)

head_dir = os.path.join(src, "data", "ct-head-headsq")
header_text = open(os.path.join(head_dir, "headsq_64x64x93_int16.mhd")).read()
NX, NY, NZ = 64, 64, 93
vox = array.array("h", open(os.path.join(head_dir, "headsq_64x64x93_int16.raw"), "rb").read())
HIP, PROXY, CONTOUR = (242, 204, 26), (38, 204, 64), (240, 64, 40)


def header(text):
    """(spacing, offset, diagonal of the direction) from a MetaImage header (diagonal ones only)."""
    nums = lambda key: [float(v) for v in re.search(key + r" = (.*)", text).group(1).split()]
    m = nums("TransformMatrix")
    assert all(m[i] == 0 for i in (1, 2, 3, 5, 6, 7)), "a diagonal direction"
    return nums("ElementSpacing"), nums("Offset"), [m[0], m[4], m[8]]


def rnd(x, app=None):
    """The nearest whole number (halves away from zero, C's lround); within 1e-6 of a half
    (the printed position's last digit) either neighbour, the app's `app` where it is one."""
    near = {int(math.copysign(math.floor(abs(v) + 0.5), v)) for v in (x - 1e-6, x + 1e-6)}
    return app if app in near else min(near, key=lambda n: abs(n - x))


def to_index(p_mm, hdr):
    """Physical LPS [mm] -> continuous voxel index: D^T (p - offset) / spacing, D diagonal."""
    sp, off, d = hdr
    return [d[a] * (p_mm[a] - off[a]) / sp[a] for a in range(3)]


# Each plane: the index axis across it, and the LPS axis and sign its columns (right) and rows (down) follow.
PLANES = {"axial": (2, (0, 1), (1, 1)), "coronal": (1, (0, 1), (2, -1)), "sagittal": (0, (1, 1), (2, -1))}


def voxel_of(plane, k, c, r, hdr, voxels, dims):
    """The voxel under pixel (c, r) of `plane` at plane index k, from the header alone."""
    normal, (ca, cs), (ra, rs) = PLANES[plane]
    d = hdr[2]
    i = [0, 0, 0]
    i[normal] = k
    i[ca] = c if d[ca] * cs > 0 else dims[ca] - 1 - c
    i[ra] = r if d[ra] * rs > 0 else dims[ra] - 1 - r
    return voxels[(i[2] * dims[1] + i[1]) * dims[0] + i[0]]


def sculpt_run(tag, mhd, events, *extra):
    """isotouch-sculpt on `mhd` (no --iso) with `events` on the simulated clock (none: `extra`
    says how it runs): (stderr, dump dir)."""
    args = []
    if events is not None:
        script = os.path.join(out, tag + "-script.json")
        json.dump({"events": events}, open(script, "w"))
        args = ["--sim-clock", "--script", script]
    d = os.path.join(out, tag)
    shutil.rmtree(d, ignore_errors=True)
    r = subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 1280x1024x24", sculpt, mhd, "--size", "640", *args,
                        "--no-overlay", "--screenshot", os.path.join(d, "window.png"),
                        "--slices-png", os.path.join(d, "slices"), *extra], capture_output=True, text=True, timeout=300)
    open(os.path.join(out, tag + ".txt"), "w").write(r.stdout + r.stderr)
    check(r.returncode == 0, f"{tag}: isotouch-sculpt exits 0 (got {r.returncode}: {r.stderr.strip()[-300:]})")
    return r.stderr, os.path.join(d, "slices")


def near_mark(s, c, r):
    """Within a mark's cross (arms of 2 pixels) of the HIP or the proxy."""
    return any((c == x and abs(r - y) <= 2) or (r == y and abs(c - x) <= 2) for x, y in (s["hip_pixel"], s["proxy_pixel"]))


def check_slice(tag, plane, meta, dump, hdr, voxels, dims, window_of=None):
    """The slice `plane` of the dump against `voxels`; the window is the range of `window_of` (default `voxels`)."""
    s = meta[plane]
    w, h, px = read_png(os.path.join(dump, plane + ".png"))
    normal = PLANES[plane][0]
    hip = to_index(meta["hip_phys_mm"], hdr)
    k = min(max(rnd(hip[normal], s["index"]), 0), dims[normal] - 1)
    check(s["index"] == k, f"{tag} {plane}: the plane through the HIP (index {k} along axis {normal}; the app's {s['index']})")
    check((w, h) == (dims[PLANES[plane][1][0]], dims[PLANES[plane][2][0]]), f"{tag} {plane}: {w}x{h} pixels, one per voxel")
    lo, hi = min(window_of or voxels), max(window_of or voxels)
    L, W, iso = (lo + hi) / 2, hi - lo, meta["isovalue"]
    grey = lambda v: round(255 * min(max((v - (L - W / 2)) / W, 0.0), 1.0))
    inside = [[voxel_of(plane, k, c, r, hdr, voxels, dims) > iso for c in range(w)] for r in range(h)]
    bad_grey = bad_contour = bone = bone_dark = 0
    for r in range(h):
        for c in range(w):
            if near_mark(s, c, r):
                continue
            v, p = voxel_of(plane, k, c, r, hdr, voxels, dims), px[r * w + c]
            edge = inside[r][c] and any(0 <= cc < w and 0 <= rr < h and not inside[rr][cc]
                                        for cc, rr in ((c - 1, r), (c + 1, r), (c, r - 1), (c, r + 1)))
            bad_contour += (p == CONTOUR) != edge
            if not edge:
                bad_grey += not (p[0] == p[1] == p[2] and abs(p[0] - grey(v)) <= 1)
            if inside[r][c]:
                bone += 1
                bone_dark += not (p == CONTOUR or p[0] >= grey(iso) - 1)
    check(abs(meta["level"] - L) < 1e-3 and abs(meta["window"] - W) < 1e-3,
          f"{tag} {plane}: the default window is the volume's range (L {meta['level']}, W {meta['window']})")
    check(bad_grey == 0, f"{tag} {plane}: every pixel off the marks and the contour shows its voxel's grey ({bad_grey} do not)")
    check(bad_contour == 0, f"{tag} {plane}: the contour pixels are the inside voxels with an outside 4-neighbour "
          f"at isovalue {iso:.6g} ({bad_contour} pixels differ)")
    if plane == "axial":
        check(bone > 50 and bone_dark == 0, f"{tag} axial: its {bone} bone voxels (> {iso:.6g}) show bright or as contour")
    hc, hr = s["hip_pixel"]
    (ca, cs), (ra, rs) = PLANES[plane][1], PLANES[plane][2]
    c_up, r_up = hdr[2][ca] * cs > 0, hdr[2][ra] * rs > 0
    exp_c = rnd(hip[ca], hc if c_up else dims[ca] - 1 - hc)
    exp_r = rnd(hip[ra], hr if r_up else dims[ra] - 1 - hr)
    exp_c, exp_r = (exp_c if c_up else dims[ca] - 1 - exp_c), (exp_r if r_up else dims[ra] - 1 - exp_r)
    check((hc, hr) == (exp_c, exp_r), f"{tag} {plane}: the HIP mark at pixel {(hc, hr)}, its index here {(exp_c, exp_r)}")
    if 0 <= hc < w and 0 <= hr < h:
        check(px[hr * w + hc] == HIP, f"{tag} {plane}: the pixel there is the HIP's yellow ({px[hr * w + hc]})")
    return px


shipped_mhd = os.path.join(head_dir, "headsq_64x64x93_int16.mhd")
hdr = header(header_text)
dims = (NX, NY, NZ)

# A first run: where the panes are, and the slices with the probe at rest.
_, dump = sculpt_run("rest", shipped_mhd, [{"after_frames": 3, "quit": True}])
meta = json.load(open(os.path.join(dump, "slices.json")))
for plane in PLANES:
    check_slice("rest", plane, meta, dump, hdr, vox, dims)

# The axial view pressed at a voxel in air in front of the face, straight ahead of the probe
# at rest (no surface within 4 voxels of it in the plane: checked here).
ax = meta["axial"]
col, row = 32, 2
target_idx = [col, row, ax["index"]]  # the shipped head's x and y run right and down in the axial view
air = all(vox[(ax["index"] * NY + y) * NX + x] < meta["isovalue"] for x in range(col - 4, col + 5) for y in range(0, row + 5))
check(air, "the pressed voxel and its surroundings are air")


def pane_cursor(s, col, row):
    """The script's cursor (fractions of the 640x480 framebuffer) over pixel (col, row) of slice `s`'s pane."""
    x = meta["column_x"] + s["pane"]["x0"] + (col + 0.5) * s["pane"]["px_per_col"]
    y = s["pane"]["y"] + s["pane"]["y0"] + (row + 0.5) * s["pane"]["px_per_row"]
    return [x / 639, y / 479]


events = [{"after_frames": 3, "cursor": pane_cursor(ax, col, row)}, {"press": "left"},
          {"after_frames": 60, "release": "left"}, {"after_frames": 2, "quit": True}]
text, dump = sculpt_run("pressed", shipped_mhd, events)
m = re.search(r"^slices   target from the axial view: index \((\S+), (\S+), (\S+)\)", text, re.M)
check(m is not None and all(abs(float(m.group(i + 1)) - target_idx[i]) <= 0.5 for i in range(3)),
      f"the press on the axial view targets voxel {target_idx} ({m.group(0) if m else 'not said'})")
pressed = json.load(open(os.path.join(dump, "slices.json")))
hip = to_index(pressed["hip_phys_mm"], hdr)
check(all(abs(hip[a] - target_idx[a]) <= 1.0 for a in range(3)),
      f"the probe went there: HIP at index ({hip[0]:.2f}, {hip[1]:.2f}, {hip[2]:.2f}), pressed {target_idx}")
shipped = {plane: check_slice("pressed", plane, pressed, dump, hdr, vox, dims) for plane in PLANES}

# The same head stored the other way: slices reversed, identity direction, offset 0.
flipped_raw = array.array("h")
for z in reversed(range(NZ)):
    flipped_raw.extend(vox[z * NX * NY:(z + 1) * NX * NY])
open(os.path.join(out, "flipped.raw"), "wb").write(flipped_raw.tobytes())
flipped_text = re.sub(r"TransformMatrix = .*", "TransformMatrix = 1 0 0 0 1 0 0 0 1", header_text)
flipped_text = re.sub(r"Offset = .*", "Offset = 0 0 0", flipped_text)
flipped_text = re.sub(r"AnatomicalOrientation = .*", "AnatomicalOrientation = RAI", flipped_text)
flipped_text = re.sub(r"ElementDataFile = .*", "ElementDataFile = flipped.raw", flipped_text)
flipped_mhd = os.path.join(out, "flipped.mhd")
open(flipped_mhd, "w").write(flipped_text)
_, fdump = sculpt_run("flipped", flipped_mhd, events)
fmeta = json.load(open(os.path.join(fdump, "slices.json")))
for plane in PLANES:
    fpx = check_slice("flipped", plane, fmeta, fdump, header(flipped_text), flipped_raw, dims)
    n = sum(a != b for a, b in zip(fpx, shipped[plane]))
    check(len(fpx) == len(shipped[plane]) and n == 0, f"flipped: the same {plane} picture as the shipped head ({n} pixels differ)")
wa = read_png(os.path.join(out, "pressed", "window.png"))
wb = read_png(os.path.join(out, "flipped", "window.png"))
col_x = meta["column_x"]
n_panes = sum(wa[2][y * wa[0] + x] != wb[2][y * wb[0] + x] for y in range(wa[1]) for x in range(col_x, wa[0]))
check(wa[:2] == wb[:2] and n_panes == 0, f"flipped: the slice views in the window's screenshot are the same ({n_panes} pixels differ)")


# With a device the slices follow it: a playback device holding the HIP at a physical point
# in air written here (trace.csv, physical frame); the planes and the HIP mark at its index.
point_mm = [54.4, 6.4, 60.0]  # index (17, 2, 52) of the shipped head
with open(os.path.join(out, "trace.csv"), "w") as f:
    f.write("t_s,hip_x_m,hip_y_m,hip_z_m\n" + "".join(f"{t},{point_mm[0] / 1e3},{point_mm[1] / 1e3},{point_mm[2] / 1e3}\n"
                                                     for t in (0, 1)))
_, ddump = sculpt_run("device", shipped_mhd, None, "--haptic", "playback:" + os.path.join(out, "trace.csv"),
                      "--frames", "30", "--no-sched-fifo")
dmeta = json.load(open(os.path.join(ddump, "slices.json")))
check(all(abs(dmeta["hip_phys_mm"][a] - point_mm[a]) < 0.01 for a in range(3)),
      f"device: the slices go through the device's HIP {dmeta['hip_phys_mm']} (played back at {point_mm})")
dmeta["hip_phys_mm"] = point_mm  # the truth: the checks below place the planes and marks from the file
for plane in PLANES:
    check_slice("device", plane, dmeta, ddump, hdr, vox, dims)

# The edited volume shows in the slices: a carve where the probe touches the left mandible,
# the edited volume saved (Ctrl+S, .mha, read here); the slices through the probe afterwards
# (a script screenshot's dump) are those of the edited voxels (the window still the range the
# session opened with), and their planes hold carved voxels. The probe then pressed away into
# air and the carve undone (Ctrl+Z) there: the slices at exit are the shipped voxels again.
def read_mha(path):
    """(header text, float32 voxels) of an uncompressed MetaImage .mha."""
    data = open(path, "rb").read()
    end = data.index(b"ElementDataFile = LOCAL\n") + len(b"ElementDataFile = LOCAL\n")
    text = data[:end].decode()
    assert "MET_FLOAT" in text and "CompressedData = True" not in text, text
    return text, array.array("f", data[end:])


edited_mha = os.path.join(out, "edited.mha")
if os.path.exists(edited_mha):
    os.remove(edited_mha)
carve = [{"after_frames": 2, "cursor": [0.56, 0.6]}, {"tool": "carve", "radius_mm": 8, "strength": 1.0},
         {"wait": "contact", "timeout_s": 30}, {"scroll": 2}, {"after_frames": 2, "press": "left"},
         {"after_frames": 12, "release": "left"}, {"wait": "edits", "timeout_s": 30},
         {"after_frames": 2, "screenshot": "carved.png"}, {"key": "s", "mods": ["ctrl"]},
         {"after_frames": 20, "cursor": pane_cursor(meta["axial"], 60, 29)}, {"press": "left"},
         {"after_frames": 60, "release": "left"}, {"after_frames": 2, "screenshot": "away.png"},
         {"key": "z", "mods": ["ctrl"]}, {"wait": "edits", "timeout_s": 30}, {"after_frames": 3, "quit": True}]
_, cdump = sculpt_run("carved", shipped_mhd, carve, "--save", edited_mha)
if os.path.exists(edited_mha):
    etext, edited = read_mha(edited_mha)
    carved_dump = os.path.join(cdump, "carved")
    cmeta = json.load(open(os.path.join(carved_dump, "slices.json")))
    umeta = json.load(open(os.path.join(cdump, "slices.json")))
    for plane in PLANES:
        check_slice("carved", plane, cmeta, carved_dump, header(etext), edited, dims, window_of=vox)
        check_slice("undone", plane, umeta, cdump, hdr, vox, dims)
        s = cmeta[plane]
        changed = sum(1 for r in range(s["height"]) for c in range(s["width"])
                      if voxel_of(plane, s["index"], c, r, hdr, vox, dims) != voxel_of(plane, s["index"], c, r, hdr, edited, dims))
        check(changed > 0, f"carved {plane}: the plane through the probe holds {changed} carved voxels")
    # Pressed away into air (lateral, in the axial plane), then undone there: the probe stays,
    # the axial slice changes back with the voxels alone.
    away_dump = os.path.join(cdump, "away")
    ameta = json.load(open(os.path.join(away_dump, "slices.json")))
    a = ameta["axial"]
    changed = sum(1 for r in range(a["height"]) for c in range(a["width"])
                  if voxel_of("axial", a["index"], c, r, hdr, vox, dims) != voxel_of("axial", a["index"], c, r, hdr, edited, dims))
    check(changed > 0 and ameta["axial"]["hip_pixel"] == umeta["axial"]["hip_pixel"] and a["index"] == umeta["axial"]["index"],
          f"away: the probe rests in air in the axial plane holding {changed} carved voxels, and stays there for the undo")
    check_slice("away", "axial", ameta, away_dump, header(etext), edited, dims, window_of=vox)
else:
    check(False, "carved: Ctrl+S saved the edited volume")

# 7. The labelled tooth at rest: the slices' colours against its label map read here.
tooth_dir = os.path.join(src, "data", "ct-tooth")
tscene = json.load(open(os.path.join(src, "scenes", "tooth-labels.json")))
thdr = header(open(os.path.join(tooth_dir, "tooth.mhd")).read())
tdims = (103, 94, 161)
traw = open(os.path.join(tooth_dir, "tooth.raw"), "rb").read()
tvox = list(struct.unpack(">%dH" % (len(traw) // 2), traw))  # MET_USHORT, MSB first
nii = gzip.open(os.path.join(tooth_dir, "tooth-labels.nii.gz")).read()
ndim = struct.unpack("<8h", nii[40:56])
check(ndim[1:4] == tdims and struct.unpack("<h", nii[70:72])[0] == 2, "tooth-labels.nii.gz: uint8 on the scan's 103x94x161 grid")
off = int(struct.unpack("<f", nii[108:112])[0])
labels = nii[off:off + tdims[0] * tdims[1] * tdims[2]]
colour = {m["label"]: tuple(math.floor(255 * c + 0.5) for c in m["color"]) for m in tscene["materials"]["list"]}
_, tdump = sculpt_run("labels", os.path.join(src, "scenes", "tooth-labels.json"), [{"after_frames": 3, "quit": True}])
tmeta = json.load(open(os.path.join(tdump, "slices.json")))
lo, hi = min(tvox), max(tvox)
L, W = (lo + hi) / 2, hi - lo
fills = {l: 0 for l in colour}
edges = {l: 0 for l in colour}
for plane in PLANES:
    s = tmeta[plane]
    w, h, px = read_png(os.path.join(tdump, plane + ".png"))
    bad = 0
    for r in range(h):
        for c in range(w):
            if near_mark(s, c, r):
                continue
            lab = voxel_of(plane, s["index"], c, r, thdr, labels, tdims)
            # The grey as the app rounds it (halves away from zero: 76.5 is 77)
            g = math.floor(255 * min(max((voxel_of(plane, s["index"], c, r, thdr, tvox, tdims) - (L - W / 2)) / W, 0.0), 1.0) + 0.5)
            p = px[r * w + c]
            if lab == 0:
                bad += not (p == CONTOUR or p == (g, g, g))
            elif p == colour[lab]:
                edges[lab] += 1
            elif all(abs(p[k] - (g + colour[lab][k]) / 2) <= 0.5 + 1e-9 for k in range(3)):
                fills[lab] += 1
            else:
                bad += 1
    check(bad == 0, f"labels {plane}: every pixel off the marks shows its label map's material colour, or grey "
          f"where there is none ({bad} do not)")
for lab, n in sorted(colour.items()):
    check(fills[lab] > 0 and edges[lab] > 0, f"labels: label {lab} filled in {fills[lab]} pixels and drawn as a boundary in {edges[lab]}")

check.finish("cli_slices")
