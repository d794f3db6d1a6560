#!/usr/bin/env python3
"""A scan opened without --iso: the isovalue isotouch-sculpt prints for each shipped volume is
checked against this file's own reading of the voxels (plain Python: the raw files parsed
here, the histogram and Otsu's thresholds computed here), and the rule it names.
`isotouch run VOLUME` makes a default touch scene: it prints the same isovalue, writes
OUT/scene.json (which runs again as a scene), and touches the surface (the contact point it
reports straddles the isovalue in the voxels read here); a file that is neither a scene nor a
volume is refused naming it.

Usage: cli_scan.py ISOTOUCH_SCULPT ISOTOUCH SOURCE_DIR OUT_DIR
Exit 0 and "PASS cli_scan" when every check holds; 77 (skipped) without xvfb-run.
"""
import array, gzip, os, re, shutil, struct, subprocess, sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cli_checks import Checks  # noqa: E402

sculpt, isotouch, src, out = sys.argv[1:5]
data = os.path.join(src, "data")
os.makedirs(out, exist_ok=True)
check = Checks()


# ---- the voxels, read here ----------------------------------------------------------------

def raw_values(path, typecode, big_endian):
    a = array.array(typecode)
    with open(path, "rb") as f:
        a.frombytes(f.read())
    if big_endian != (sys.byteorder == "big"):
        a.byteswap()
    return a


def head():
    return raw_values(os.path.join(data, "ct-head-headsq/headsq_64x64x93_int16.raw"), "h", False)


def tooth():  # tooth.nhdr: unsigned short, endian big
    return raw_values(os.path.join(data, "ct-tooth/tooth.raw"), "H", True)


def engine():  # NIfTI-1: datatype at byte 70, vox_offset at 108; uint8 (datatype 2)
    d = gzip.open(os.path.join(data, "ct-engine/engine.nii.gz")).read()
    assert struct.unpack("<h", d[70:72])[0] == 2, "engine.nii.gz is not uint8"
    return array.array("B", d[int(struct.unpack("<f", d[108:112])[0]):])


def chest():
    return raw_values(os.path.join(data, "ct-chest-lungdx-a0001/chest_ct_lungdx_a0001_256x256x64_int16.raw"), "h", False)


# ---- histogram and Otsu, written here -----------------------------------------------------

def histogram(values, bins=256):
    lo, hi = min(values), max(values)
    counts = [0] * bins
    scale = bins / (hi - lo)
    for v in values:
        counts[min(int((v - lo) * scale), bins - 1)] += 1
    return lo, hi, counts


def otsu(lo, hi, counts, classes):
    """Bin edges maximising sum_k n_k mu_k^2 over every split into `classes` runs of bins."""
    w = (hi - lo) / len(counts)
    n = [0.0]
    s = [0.0]
    for i, c in enumerate(counts):
        n.append(n[-1] + c)
        s.append(s[-1] + c * (lo + (i + 0.5) * w))

    def term(a, b):
        m = n[b] - n[a]
        return (s[b] - s[a]) ** 2 / m if m > 0 else 0.0

    L = len(counts)
    if classes == 2:
        best = max(range(1, L), key=lambda t: (term(0, t) + term(t, L), -t))
        return [lo + best * w]
    best, b1, b2 = -1.0, 0, 0
    for t1 in range(1, L - 1):
        for t2 in range(t1 + 1, L):
            v = term(0, t1) + term(t1, t2) + term(t2, L)
            if v > best:
                best, b1, b2 = v, t1, t2
    return [lo + b1 * w, lo + b2 * w]


# ---- what the programs print ------------------------------------------------------------

def sculpt_isovalue(volume, tag):
    """Runs isotouch-sculpt on `volume` for 2 frames under Xvfb: (isovalue, rule line)."""
    r = subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 1280x1024x24", sculpt, volume, "--frames", "2",
                        "--size", "256", "--no-overlay"], capture_output=True, text=True, timeout=300)
    with open(os.path.join(out, tag + ".txt"), "w") as f:
        f.write(r.stdout + r.stderr)
    m = re.search(r"^sculpt   isovalue (\S+) \(inside (above|below)\), chosen by (.*)$", r.stderr, re.M)
    check(r.returncode == 0, f"{tag}: isotouch-sculpt exits 0 (got {r.returncode})")
    check(m is not None, f"{tag}: isotouch-sculpt prints the isovalue and its rule")
    check("sculpt   camera up: superior, front: anterior" in r.stderr, f"{tag}: the window opens upright (camera up: superior)")
    return (float(m.group(1)), m.group(3)) if m else (float("nan"), "")


def expect_otsu(tag, volume, values):
    lo, hi, counts = histogram(values)
    upper = otsu(lo, hi, counts, 3)[1]
    skin = otsu(lo, hi, counts, 2)[0]
    iso, rule = sculpt_isovalue(volume, tag)
    print(f"     {tag}: printed {iso}, three-class Otsu here {upper:.6g}, two-class {skin:.6g}, range {lo}..{hi}")
    check(abs(iso - upper) <= 1e-3 * max(1.0, abs(upper)), f"{tag}: isovalue {iso} is the upper three-class Otsu threshold {upper:.6g}")
    check("three-class Otsu" in rule, f"{tag}: the rule names the three-class Otsu: {rule}")
    return iso, skin


if shutil.which("xvfb-run") is None:
    print("SKIP: no xvfb-run")
    sys.exit(77)

head_mhd = os.path.join(data, "ct-head-headsq/headsq_64x64x93_int16.mhd")
iso, skin = expect_otsu("head", head_mhd, head())
head_iso = iso
check(iso > skin + 300, f"head: bone ({iso}) well above the two-class threshold on skin ({skin:.6g})")
expect_otsu("tooth", os.path.join(data, "ct-tooth/tooth.nhdr"), tooth())
expect_otsu("engine", os.path.join(data, "ct-engine/engine.nii.gz"), engine())

# CT in HU: the chest's air is -1024; it opens in the bone band 150..500 HU.
c = chest()
check(min(c) == -1024, "chest: its minimum, read here, is -1024 (air in HU)")
for tag, vol in (("chest", os.path.join(data, "ct-chest-lungdx-a0001/chest_ct_lungdx_a0001_256x256x64_int16.mhd")),
                 ("chest-dicom", os.path.join(data, "ct-chest-lungdx-a0001/dicom-5mm"))):
    iso, rule = sculpt_isovalue(vol, tag)
    check(150 <= iso <= 500, f"{tag}: isovalue {iso} in the bone band 150..500 HU")
    check(rule.startswith("CT in HU"), f"{tag}: the rule says CT in HU: {rule}")
check("modality CT" in rule, f"chest-dicom: recognised by its DICOM modality ({rule})")

# The panel's presets (CT in HU), from a script: soft tissue / skin restarts the session in the
# skin band -500..-100 HU; a name that is no preset is said and changes nothing.
preset_script = os.path.join(out, "preset.json")
with open(preset_script, "w") as f:
    f.write('{"events": [{"after_frames": 2, "preset": "soft tissue / skin"}, {"after_frames": 2, "preset": "marrow"}, '
            '{"after_frames": 1, "quit": true}]}\n')
r = subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 1280x1024x24", sculpt,
                    os.path.join(data, "ct-chest-lungdx-a0001/chest_ct_lungdx_a0001_256x256x64_int16.mhd"),
                    "--size", "256", "--script", preset_script], capture_output=True, text=True, timeout=300)
m = re.search(r"^sculpt   isovalue (\S+): the session restarts", r.stderr, re.M)
check(r.returncode == 0 and m is not None and -500 <= float(m.group(1)) <= -100,
      f"chest: the soft tissue / skin preset restarts at an isovalue in -500..-100 HU ({m.group(0) if m else r.stderr[-300:]})")
check('sculpt   no preset "marrow" for this volume' in r.stderr, "chest: an unknown preset is said")
# The restarted session says (and its stats panel shows) how the isovalue was set.
m2 = re.search(r"^sculpt   isovalue (\S+) \(inside above\), chosen by the preset soft tissue / skin$", r.stderr, re.M)
check(m is not None and m2 is not None and float(m2.group(1)) == float(m.group(1)),
      f"chest: after the preset, the rule line says so ({m2.group(0) if m2 else 'no line'})")

# A .vdb opens at the isovalue it stores (export --iso writes it), one without at the histogram's.
vdb = os.path.join(out, "head-1150.vdb")
r = subprocess.run([isotouch, "export", head_mhd, "--iso", "1150", "--inside", "above", "--vdb", vdb], capture_output=True, text=True)
check(r.returncode == 0, f"export --vdb exits 0 ({r.stderr.strip()[-200:]})")
iso, rule = sculpt_isovalue(vdb, "head-vdb")
check(iso == 1150 and "stored in the file" in rule, f"head .vdb: opens at its stored 1150 ({iso}, {rule})")
# export --vdb without --iso: the head's own isovalue (the upper three-class Otsu, computed
# here), its rule printed, and stored in the .vdb, which opens at it.
vdb = os.path.join(out, "head-auto.vdb")
r = subprocess.run([isotouch, "export", head_mhd, "--vdb", vdb], capture_output=True, text=True)
m = re.search(r"^isosurface  tau (\S+), inside above \(chosen by (.*)\)$", r.stdout, re.M)
check(r.returncode == 0 and m is not None and abs(float(m.group(1)) - head_iso) <= 1e-3 * head_iso
      and "three-class Otsu" in m.group(2),
      f"export --vdb without --iso: the head's Otsu isovalue {head_iso:.6g} and its rule ({m.group(0) if m else r.stderr.strip()[-200:]})")
iso, rule = sculpt_isovalue(vdb, "head-auto-vdb")
check(abs(iso - head_iso) <= 1e-3 * head_iso and "stored in the file" in rule, f"that .vdb opens at the value it stores ({iso}, {rule})")


# ---- isotouch run VOLUME -------------------------------------------------------------------

def mhd_header(path):
    h = {}
    for line in open(path):
        k, _, v = line.partition("=")
        h[k.strip()] = v.strip()
    return h


def straddles(values, dims, mhd, point_m, iso):
    """The 2x2x2 voxels around a physical point [m] hold values on both sides of iso."""
    h = mhd_header(mhd)
    D = [float(x) for x in h["TransformMatrix"].split()]  # row-major; column a = index axis a
    o = [float(x) for x in h["Offset"].split()]
    sp = [float(x) for x in h["ElementSpacing"].split()]
    r = [point_m[i] * 1e3 - o[i] for i in range(3)]
    idx = [sum(D[row * 3 + a] * r[row] for row in range(3)) / sp[a] for a in range(3)]  # D^T r / spacing
    base = [int(idx[a]) for a in range(3)]
    vals = []
    for dz in (0, 1):
        for dy in (0, 1):
            for dx in (0, 1):
                x, y, z = base[0] + dx, base[1] + dy, base[2] + dz
                if 0 <= x < dims[0] and 0 <= y < dims[1] and 0 <= z < dims[2]:
                    vals.append(values[(z * dims[1] + y) * dims[0] + x])
    return bool(vals) and min(vals) <= iso <= max(vals), idx


def run_volume(tag, volume, expect_iso):
    """isotouch run VOLUME: (summary, scene) after checking what it printed and wrote."""
    folder = os.path.join(out, "run-" + tag)
    shutil.rmtree(folder, ignore_errors=True)
    r = subprocess.run([isotouch, "run", volume, "--quiet", "--out", folder], capture_output=True, text=True, timeout=600)
    with open(folder + ".txt", "w") as f:
        f.write(r.stdout + r.stderr)
    check(r.returncode == 0, f"run {tag}: exits 0 (got {r.returncode}; {r.stderr.strip()[-300:]})")
    m = re.search(r"^scene    isovalue (\S+) \(inside above\), chosen by (.*)$", r.stdout, re.M)
    check(m is not None and abs(float(m.group(1)) - expect_iso) <= 1e-3 * max(1, abs(expect_iso)),
          f"run {tag}: prints the isovalue {expect_iso:.6g} and its rule ({m.group(0) if m else 'no line'})")
    check(re.search(r"^scene    the probe approaches along [+-][xyz] \(index\) from the [LRAPSI] side", r.stdout, re.M)
          is not None, f"run {tag}: says where the probe comes from")
    scene_file = os.path.join(folder, "scene.json")
    check(f"written to {scene_file}" in r.stdout, f"run {tag}: says it wrote {scene_file}")
    check(re.search(r"^picture  surface.png, up: (superior|anterior)$", r.stdout, re.M) is not None,
          f"run {tag}: says the picture's up in patient axes")
    try:
        scene = json.load(open(scene_file))
        summary = json.load(open(os.path.join(folder, "summary.json")))
    except (OSError, ValueError) as e:
        check(False, f"run {tag}: scene.json and summary.json read back ({e})")
        return None, None
    check(abs(scene["isovalue"] - expect_iso) <= 1e-3 * max(1, abs(expect_iso)), f"run {tag}: scene.json holds the isovalue")
    rule = m.group(2) if m else "?"
    check(f": isovalue {m.group(1) if m else '?'} (inside above), chosen by {rule}; the probe approaches" in scene.get("description", ""),
          f"run {tag}: scene.json's description says the isovalue and its rule once ({scene.get('description', '')[:160]!r})")
    check(summary["status"] == "complete" and summary["contact"]["ticks"] > 100 and summary["contact"]["max_force_n"] > 0.1,
          f"run {tag}: the probe touched ({summary['contact']['ticks']} contact ticks, max {summary['contact']['max_force_n']:.3g} N)")
    return summary, scene_file


import json
head_iso = otsu(*histogram(head()), 3)[1]
summary, scene_file = run_volume("head", head_mhd, head_iso)
if summary:
    ok, idx = straddles(head(), (64, 64, 93), head_mhd, summary["script"]["contact_point_m"], head_iso)
    check(ok, f"run head: its contact point (index {[round(i, 1) for i in idx]}) is on the bone isosurface of the voxels read here")
    r = subprocess.run([isotouch, "run", scene_file, "--quiet", "--out", os.path.join(out, "run-head-again")],
                       capture_output=True, text=True, timeout=600)
    check(r.returncode == 0, f"run head: the scene.json it wrote runs as a scene (exit {r.returncode})")
run_volume("chest-dicom", os.path.join(data, "ct-chest-lungdx-a0001/dicom-5mm"), 300)

# Neither a scene nor a volume: one line naming the file, exit 1, no raw JSON parser text.
bad = os.path.join(src, "tests", "CMakeLists.txt")
r = subprocess.run([isotouch, "run", bad, "--out", os.path.join(out, "run-bad")], capture_output=True, text=True)
check(r.returncode == 1 and f"{bad}: neither a scene (JSON) nor a volume" in r.stderr and "parse error" not in r.stderr,
      f"run on a text file: exit 1 and names it ({r.returncode}: {r.stderr.strip()[-200:]})")

check.finish("cli_scan")
