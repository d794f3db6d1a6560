"""Judge igtl_hand_peer's logs (cli_haptic_igtl_delay.sh): the device's own motion and energy.
Usage: igtl_hand_check.py PLAIN_PEER_LOG CONTROLLED_PEER_LOG"""
import statistics
import sys


def read(path):
    ticks, energy, pc, still, late = [], None, None, None, None
    for line in open(path):
        w = line.split()
        if w[:1] == ["still"]:
            still = float(w[1])
        elif w[:1] == ["tick"]:
            ticks.append(tuple(float(v) for v in w[1:5]))
        elif w[:1] == ["energy"]:
            energy = float(w[1])
        elif w[:1] == ["pc"]:
            pc = (int(w[1]), float(w[2]))
        elif w[:1] == ["late"]:
            late = (int(w[1]), float(w[2]))
    if energy is None or still is None or late is None or len(ticks) < 1000:
        print(f"FAIL {path}: the peer's run did not finish ({len(ticks)} ticks)")
        sys.exit(1)
    return ticks, energy, pc, still, late


def half_peak_to_peak(s, w=100):
    """The largest half peak-to-peak of positions s within any w ticks (100 ms: the wall's mode
    at K 800 N/m and 80 g is about 16 Hz, a period fits), not the slow creep of a damped
    stylus settling into its rest over seconds."""
    return max(0.5 * (max(s[i:i + w]) - min(s[i:i + w])) for i in range(0, len(s) - w + 1, 10))


def dropouts(window, resting_n):
    """Times [s] where the force held from the link fell under half the resting force and
    came back: a force the link did not deliver (the isotouch side's stall, a late message)."""
    out, low = [], False
    for t, _, _, h in window:
        if h < 0.5 * resting_n and not low:
            out.append(t)
        low = h < 0.5 * resting_n
    return out


def judge(path):
    """The press judged over 2.5 s from 200 ms after the contact and the hand's stop,
    whichever is later, in ten 250 ms parts: the oscillation of each part (half_peak_to_peak),
    their median (a limit cycle lasts: it shows in every part; a single disturbance, such as
    a force the link dropped, in one or two) and largest, the dropouts, the mean depth and
    force over the last 0.5 s, energy [J], the controller's (active ticks, dissipated [J]) and
    the loop's (late ticks, worst lag [s])."""
    ticks, energy, pc, still, late = read(path)
    contact = next((t for t, _, f, _ in ticks if f > 0.05), None)
    if contact is None:
        print(f"FAIL {path}: the stylus never touched the skull (largest force {max(f for _, _, f, _ in ticks):.3f} N)")
        sys.exit(1)
    # A fixed window: the run's stop (its force ramped off, the hand then pushing the stylus
    # in) comes later, its live part lasting 6.3 s from after its 1 s rate measurement, both
    # counted from the connection.
    since = max(contact, still) + 0.2
    end = since + 2.5
    if ticks[-1][0] < end + 0.5:
        print(f"FAIL {path}: the run ended at {ticks[-1][0]:.3f} s, before the judged window's end {end:.3f} s + 0.5 s")
        sys.exit(1)
    window = [tk for tk in ticks if since <= tk[0] < end]
    if len(window) < 2400:
        print(f"FAIL {path}: only {len(window)} ticks in the judged 2.5 s")
        sys.exit(1)
    parts = [half_peak_to_peak([s for t, s, _, _ in window if since + 0.25 * i <= t < since + 0.25 * (i + 1)])
             for i in range(10)]
    last = [tk for tk in window if tk[0] >= end - 0.5]
    mean_s = sum(tk[1] for tk in last) / len(last)
    mean_f = sum(tk[2] for tk in last) / len(last)
    return dict(contact=contact, median=statistics.median(parts), largest=max(parts), s=mean_s, f=mean_f,
                energy=energy, pc=pc, late=late, since=since, end=end, drops=dropouts(window, mean_f))


plain = judge(sys.argv[1])
controlled = judge(sys.argv[2])
k = 800.0
for name, r in (("without controller", plain), ("with controller", controlled)):
    drops = ", ".join(f"{t:.3f}" for t in r["drops"][:5]) or "none"
    print(f"{name}: contact at {r['contact']:.3f} s; from {r['since']:.3f} s to {r['end']:.3f} s the oscillation "
          f"(half peak-to-peak within 100 ms) of ten 250 ms parts: median {r['median']:.4f} mm, largest "
          f"{r['largest']:.4f} mm; resting {r['s']:.2f} mm in with {r['f']:.3f} N; the link's force under half of "
          f"that {len(r['drops'])} times (at {drops} s); device energy out {r['energy']:.3g} J; controller active "
          f"{r['pc'][0]} ticks ({r['pc'][1]:.3g} J); the peer's loop late (> 2 ms) on {r['late'][0]} ticks, "
          f"worst {1e3 * r['late'][1]:.1f} ms")
ok = True
if plain["median"] <= 0.5:
    print(f"FAIL: without the controller the press settled (median {plain['median']:.4f} mm): the test shows nothing")
    ok = False
if controlled["median"] >= 0.1:
    print(f"FAIL: with the controller at the device end the stylus keeps moving: median {controlled['median']:.4f} mm "
          "(>= 0.1 mm)")
    ok = False
if not controlled["f"] > 0.3:
    print(f"FAIL: with the controller the stylus does not rest on the skull ({controlled['f']:.3f} N)")
    ok = False
# The wall's stored energy at rest: F^2 / (2 K).
tolerance = 0.01 * controlled["f"] ** 2 / (2 * k)
if controlled["energy"] > tolerance:
    print(f"FAIL: with the controller the force did {controlled['energy']:.3g} J more work on the device than its "
          f"damper took out (allowed {tolerance:.3g} J)")
    ok = False
sys.exit(0 if ok else 1)
