#!/usr/bin/env python3
"""Writes the shipped tooth label maps from the shipped tooth CT (data/ct-tooth/tooth.raw).

Each voxel is labelled by its own value, the thresholds below (read off the scan's histogram:
air and the mount ~350-450, dentin ~750-850, enamel ~1150-1250, the pulp canal darker than
the air, ~200-300):
    enamel  [1000, 65536)  label 1
    dentin  [600, 1000)    label 2
    pulp    [0, 300)       label 3
    none    anything else  label 0  (air, the mount, and the partial-volume shell between
                                     dentin and pulp, which passes through the air's values)
The enamel's outer rim is partial volume too: 3,559 voxels with values in [600, 1000) that
touch both enamel (>= 1000) and air ([300, 600)) across a face are labelled dentin, a thin
dentin skin over the enamel where the tooth meets the air (counted by face neighbours on the
shipped scan). A label by value alone cannot tell them from dentin; they are kept so the
three forms stay the same thresholds.
The same ranges are scenes/tooth-transfer.json's transfer function, so the three shipped
forms hold the same labels voxel for voxel (tests/test_materials.cpp checks it).

Outputs, on the scan's grid (103 x 94 x 161 voxels of 1 mm, origin 0, identity direction):
    data/ct-tooth/tooth-labels.nii.gz  a NIfTI label map (TotalSegmentator's form), uint8
    data/ct-tooth/tooth.seg.nrrd       a 3D Slicer segmentation (gzip NRRD, one layer) with
                                       its SegmentN_Name / _LabelValue / _Layer / _Color keys
Standard library only. Usage: tools/make_tooth_labels.py [REPO_ROOT]
"""
import gzip
import os
import struct
import sys
from array import array

DIMS = (103, 94, 161)
SEGMENTS = [  # name, label, [lo, hi), colour
    ("enamel", 1, (1000, 65536), "0.95 0.93 0.80"),
    ("dentin", 2, (600, 1000), "0.90 0.75 0.45"),
    ("pulp", 3, (0, 300), "0.85 0.20 0.20"),
]


def labels(raw_path):
    values = array("H")
    with open(raw_path, "rb") as f:
        values.frombytes(f.read())
    if sys.byteorder == "little":
        values.byteswap()  # tooth.raw is big-endian (tooth.nhdr)
    n = DIMS[0] * DIMS[1] * DIMS[2]
    if len(values) != n:
        sys.exit(f"{raw_path}: {len(values)} voxels, expected {n}")
    lut = bytearray(65536)
    for _, label, (lo, hi), _ in SEGMENTS:
        for v in range(lo, min(hi, 65536)):
            lut[v] = label
    return bytes(lut[v] for v in values)


def write_nifti(path, data):
    # NIfTI-1, uint8, 1 mm; sform (code 1) RAS = (-x, -y, z): ITK's LPS grid is then the
    # scan's (origin 0, identity direction). Gzip with mtime 0: the same bytes every run.
    h = bytearray(352)
    struct.pack_into("<i", h, 0, 348)
    struct.pack_into("<8h", h, 40, 3, DIMS[0], DIMS[1], DIMS[2], 1, 1, 1, 1)
    struct.pack_into("<hh", h, 70, 2, 8)  # DT_UNSIGNED_CHAR, bitpix
    struct.pack_into("<8f", h, 76, 1, 1, 1, 1, 1, 1, 1, 1)
    struct.pack_into("<f", h, 108, 352.0)  # vox_offset
    h[123] = 2  # xyzt_units: mm
    struct.pack_into("<hh", h, 252, 0, 1)  # qform_code 0, sform_code 1
    struct.pack_into("<12f", h, 280, -1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1, 0)
    h[148:148 + 80] = b"isotouch tooth labels: tools/make_tooth_labels.py".ljust(80, b"\0")  # descrip
    h[344:348] = b"n+1\0"
    with open(path, "wb") as f:
        f.write(gzip.compress(bytes(h) + data, 9, mtime=0))


def write_seg_nrrd(path, data):
    lines = [
        "NRRD0004", "type: unsigned char", "dimension: 3", "space: left-posterior-superior",
        f"sizes: {DIMS[0]} {DIMS[1]} {DIMS[2]}", "space directions: (1,0,0) (0,1,0) (0,0,1)",
        "kinds: domain domain domain", "encoding: gzip", "space origin: (0,0,0)",
    ]
    for i, (name, label, _, colour) in enumerate(SEGMENTS):
        lines += [f"Segment{i}_Name:={name}", f"Segment{i}_LabelValue:={label}", f"Segment{i}_Layer:=0",
                  f"Segment{i}_Color:={colour}", f"Segment{i}_ID:=Segment_{i + 1}"]
    with open(path, "wb") as f:
        f.write(("\n".join(lines) + "\n\n").encode())
        f.write(gzip.compress(data, 9, mtime=0))


def main():
    root = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..")
    folder = os.path.join(root, "data", "ct-tooth")
    data = labels(os.path.join(folder, "tooth.raw"))
    write_nifti(os.path.join(folder, "tooth-labels.nii.gz"), data)
    write_seg_nrrd(os.path.join(folder, "tooth.seg.nrrd"), data)
    counts = [data.count(bytes([k])) for k in range(4)]
    print("voxels per label 0..3:", counts)


if __name__ == "__main__":
    main()
