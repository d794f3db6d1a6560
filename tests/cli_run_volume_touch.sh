#!/bin/bash
# `isotouch run VOLUME` on a shipped scan: the touch planned on the true isosurface keeps the
# stroke on the surface and the force under the limit. Read from the run folder: the stroke's
# contact share from summary.json, recomputed from trace.csv (its contact column between the
# phases summary.json gives), and the share of contact ticks whose |F| (trace.csv) is under
# 0.95 of the limit (summary.json's servo.force_limit_n). With MIN_WALKED: the stroke walked
# on the surface is at least that share of the length the scene asked (scene.json) - a thin
# rib under the ray holds a few millimetres only. The overview: overview.png is a PNG and
# report.md shows it, saying what is up.
# usage: cli_run_volume_touch.sh ISOTOUCH VOLUME OUT_DIR [MIN_WALKED]
set -u
bin=$1 vol=$2 out=$3 min_walked=${4:-0}
rm -rf "$out"
"$bin" run "$vol" -o "$out" --quiet > "$out.log" 2>&1
rc=$?
if [ $rc -ne 0 ]; then cat "$out.log"; echo "FAIL: isotouch run exited $rc"; exit 1; fi
python3 - "$out" "$min_walked" <<'PY'
import csv, json, math, sys
d, min_walked = sys.argv[1], float(sys.argv[2])
s = json.load(open(d + "/summary.json"))
limit = s["servo"]["force_limit_n"]
t0, t1 = s["script"]["phases_s"]["stroke"], s["script"]["phases_s"]["lift"]
stroke = stroke_contact = contact = under = 0
with open(d + "/trace.csv") as f:
    for row in csv.DictReader(f):
        t, c = float(row["t_s"]), row["contact"] == "1"
        if t0 <= t < t1:
            stroke += 1
            stroke_contact += c
        if c:
            contact += 1
            under += math.sqrt(sum(float(row[k]) ** 2 for k in ("f_x_n", "f_y_n", "f_z_n"))) < 0.95 * limit
share = stroke_contact / stroke if stroke else 0.0
under_share = under / contact if contact else 0.0
print(f"stroke {stroke_contact} of {stroke} ticks in contact ({100 * share:.1f} %; summary.json says "
      f"{s['script']['stroke_contact_fraction']}); {under} of {contact} contact ticks under 0.95 of {limit} N "
      f"({100 * under_share:.1f} %); plan {s['script']['plan']}")
asked = json.load(open(d + "/scene.json"))["script"]["stroke_length_m"]
walked = s["script"]["plan"]["stroke_length_m"] / asked
print(f"stroke walked {1e3 * s['script']['plan']['stroke_length_m']:.2f} of {1e3 * asked:.1f} mm asked")
report = open(d + "/report.md").read()
overview_ok = open(d + "/overview.png", "rb").read(8) == b"\x89PNG\r\n\x1a\n" and "](overview.png)" in report
overview_ok = overview_ok and "superior up" in report
print("overview.png shown in report.md, superior up" if overview_ok else "FAIL: overview.png missing or not in report.md")
ok = stroke > 0 and share >= 0.8 and under_share >= 0.9 and walked >= min_walked and overview_ok
ok = ok and abs(s["script"]["stroke_contact_fraction"] - share) < 1e-9
ok = ok and abs(s["contact"]["fraction_under_95pct_limit"] - under_share) < 1e-9
print("PASS planned touch" if ok else f"FAIL: want >= 80 % of the stroke in contact, >= 90 % of contact ticks under 0.95 of the limit, the summary agreeing, >= {100 * min_walked:.0f} % of the asked stroke walked and the overview shown")
PY
