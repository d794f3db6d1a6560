# compare_forces.py LOG REC FRAME PRINTED_MAX: the forces a test double RECEIVED (its log, in
# its SDK's frame: FRAME hd or fd) against the servo's (a --record recording, device axes).
# Passes (exit 0) when the summed received force, mapped into isotouch's device frame by the
# SDK's documented axes (written here, not taken from the backend), points where the servo's
# does (cosine > 0.99), the largest received |F| is at most the one the run printed (the
# servo's largest write; the device thread may zero a write after a stall, never raise one)
# and at least 0.8 of it (units: mm for m or the like would be off by 1000), at most the
# scene's limit (3.3 N), and the last force received is an exact zero.
import json, math, sys
log, rec, frame, printed = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
def to_iso(f):  # the SDK's frame -> isotouch's device frame, written independently of the backend
    return (f[0], -f[2], f[1]) if frame == "hd" else (f[1], -f[0], f[2])
recv = []
for line in open(log).readlines()[1:]:
    t, fx, fy, fz, en, van = line.strip().split(",")
    recv.append((float(t), to_iso((float(fx), float(fy), float(fz))), int(en)))
sent = [json.loads(l)["force"] for l in open(rec).readlines()[1:] if '"force"' in l]
def total(v): return [sum(x[i] for x in v) for i in range(3)]
def norm(v): return math.sqrt(sum(c * c for c in v))
R, S = total([r[1] for r in recv]), total(sent)
cos = sum(a * b for a, b in zip(R, S)) / (norm(R) * norm(S))
fmax = max(norm(r[1]) for r in recv)
print(f"received sum {R} servo sum {S} cos {cos:.4f} max|F| received {fmax:.4f} N enabled {sum(r[2] for r in recv)}/{len(recv)}")
last = recv[-1][1]
problems = []
if not cos > 0.99: problems.append(f"direction: cosine {cos:.4f} between the received and the servo's forces")
if not 0.8 * printed <= fmax <= printed + 1e-3: problems.append(f"max |F| received {fmax:.4f} N, the servo's largest {printed} N")
# The clamp scales to 3.3 N; its norm may round one ulp up.
if fmax > 3.3 + 1e-6: problems.append(f"max |F| received {fmax:.4f} N beyond the scene's 3.3 N")
if any(c != 0 for c in last): problems.append(f"last force received {last}, not zero")
for p in problems: print("FAIL:", p)
sys.exit(1 if problems else 0)
