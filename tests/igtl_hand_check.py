"""Judge igtl_hand_peer's logs (cli_haptic_igtl_delay.sh): the device's own motion and energy.
Usage: igtl_hand_check.py PLAIN_PEER_LOG CONTROLLED_PEER_LOG [SERVE_CONTROLLED_PEER_LOG]"""
import statistics
import sys


WINDOW_S, PART_S, SETTLE_S = 5.5, 0.25, 1.0


def read(path):
    ticks, energy, pc, still, late, lags = [], None, None, None, None, []
    for line in open(path):
        w = line.split()
        if w[:1] == ["lag"]:
            lags.append(float(w[1]))
        elif w[:1] == ["still"]:
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
    return ticks, energy, pc, still, late, lags


def half_peak_to_peak(s, w=100):
    """The largest half peak-to-peak of positions s within any w ticks (100 ms: the wall's mode
    at K 800 N/m and 80 g is about 16 Hz, a period fits), not the slow creep of a damped
    stylus settling into its rest over seconds."""
    return max(0.5 * (max(s[i:i + w]) - min(s[i:i + w])) for i in range(0, len(s) - w + 1, 10))


def dropouts(window, resting_n, surface_mm, judged_from_s):
    """(pressed, bounced): times [s] where the force held from the link stepped from over half
    the resting force to an exact zero. Pressed: the stylus was inside the surface (deeper
    than at contact) a round trip (10 ticks) before: a zero isotouch sent while it pressed
    (its stale or stall rule's zero on a loaded machine, then its ramp). Bounced: it was not -
    the stylus left the skull, and the zero is the wall's own answer (judged, not excused),
    from judged_from_s on (before it the hand still moves the stylus in)."""
    pressed, bounced = [], []
    step = max(0.5 * resting_n, 0.05)  # a stylus that does not rest (the plain run): 50 mN
    for i in range(11, len(window)):
        (_, _, _, h0), (t, _, _, h) = window[i - 1], window[i]
        if h0 > step and h == 0.0:
            (pressed if window[i - 10][1] > surface_mm else bounced).append(t)
    bounced = [t for t in bounced if t >= judged_from_s]
    return pressed, bounced


def judge(path):
    """The press judged over WINDOW_S from 200 ms after the contact and the hand's stop,
    whichever is later, in PART_S parts: the oscillation of each part (half_peak_to_peak);
    their median (a limit cycle lasts: it shows in every part); the parts clean of
    disturbances - the link's dropouts and the peer loop's own lags over a link period -
    (none in the part or the SETTLE_S before it: the stylus, shaken, then settles) and their
    largest; the mean depth and force over the last 0.5 s, energy [J], the controller's
    (active ticks, dissipated [J]) and the loop's (late ticks, worst lag [s])."""
    ticks, energy, pc, still, late, lags = read(path)
    contact = next((t for t, _, f, _ in ticks if f > 0.05), None)
    if contact is None:
        print(f"FAIL {path}: the stylus never touched the skull (largest force {max(f for _, _, f, _ in ticks):.3f} N)")
        sys.exit(1)
    # A fixed window: the run's stop (its force ramped off, the hand then pushing the stylus
    # in) comes later, its live part lasting 9.3 s from after its 1 s rate measurement, both
    # counted from the connection.
    since = max(contact, still) + 0.2
    end = since + WINDOW_S
    if ticks[-1][0] < end + 0.5:
        print(f"FAIL {path}: the run ended at {ticks[-1][0]:.3f} s, before the judged window's end {end:.3f} s + 0.5 s")
        sys.exit(1)
    window = [tk for tk in ticks if since <= tk[0] < end]
    if len(window) < 0.96e3 * WINDOW_S:
        print(f"FAIL {path}: only {len(window)} ticks in the judged {WINDOW_S} s")
        sys.exit(1)
    last = [tk for tk in window if tk[0] >= end - 0.5]
    mean_s = sum(tk[1] for tk in last) / len(last)
    mean_f = sum(tk[2] for tk in last) / len(last)
    surface = next(s for t, s, f, _ in ticks if f > 0.05)  # the stylus at contact [mm]
    drops, bounces = dropouts([tk for tk in ticks if since - SETTLE_S <= tk[0] < end], mean_f, surface, since)
    events = sorted(drops + lags)
    parts, clean = [], []
    for i in range(round(WINDOW_S / PART_S)):
        a, b = since + PART_S * i, since + PART_S * (i + 1)
        parts.append(half_peak_to_peak([s for t, s, _, _ in window if a <= t < b]))
        if not any(a - SETTLE_S <= t < b for t in events):
            clean.append(parts[-1])
    return dict(contact=contact, median=statistics.median(parts), largest=max(parts), parts=len(parts), clean=clean,
                s=mean_s, f=mean_f, energy=energy, pc=pc, late=late, since=since, end=end, drops=drops, lags=lags,
                bounces=bounces)


plain = judge(sys.argv[1])
controlled = [(f"with controller ({name})", judge(path)) for name, path in zip(("run", "serve"), sys.argv[2:])]
k = 800.0
for name, r in [("without controller", plain)] + controlled:
    drops = ", ".join(f"{t:.3f}" for t in r["drops"][:5]) or "none"
    clean = f"{max(r['clean']):.4f} mm" if r["clean"] else "-"
    print(f"{name}: contact at {r['contact']:.3f} s; from {r['since']:.3f} s to {r['end']:.3f} s the oscillation "
          f"(half peak-to-peak within 100 ms) of {r['parts']} parts of {1e3 * PART_S:.0f} ms: median "
          f"{r['median']:.4f} mm, largest {r['largest']:.4f} mm, largest of the {len(r['clean'])} parts clean of "
          f"disturbances {clean}; dropouts (the link's force stepping to an exact zero while the stylus pressed) "
          f"{len(r['drops'])} (at {drops} s), bounces off the skull {len(r['bounces'])}; the peer loop's lags over "
          f"10 ms {len(r['lags'])}; resting "
          f"{r['s']:.2f} mm in with {r['f']:.3f} N; device energy out {r['energy']:.3g} J; controller active "
          f"{r['pc'][0]} ticks ({r['pc'][1]:.3g} J); the peer's loop late (> 2 ms) on {r['late'][0]} ticks, "
          f"worst {1e3 * r['late'][1]:.1f} ms")
ok = True
if plain["median"] <= 0.5:
    print(f"FAIL: without the controller the press settled (median {plain['median']:.4f} mm): the test shows nothing")
    ok = False
skipped = False
for name, r in controlled:
    if r["bounces"]:
        print(f"FAIL: {name} the stylus bounced off the skull {len(r['bounces'])} times (at "
              f"{', '.join(f'{t:.3f}' for t in r['bounces'][:5])} s)")
        ok = False
    elif len(r["clean"]) < 3:
        # Not judged: the machine disturbed the link (isotouch's zeros, the peer's lags) too often.
        print(f"SKIP: {name} only {len(r['clean'])} of {r['parts']} parts are clean of disturbances (3 needed): "
              "the link's dropouts or the peer's lags disturbed most of the window (a loaded machine)")
        skipped = True
    elif max(r["clean"]) >= 0.1:
        print(f"FAIL: {name} at the device end the stylus moves {max(r['clean']):.4f} mm (>= 0.1 mm) in a part clean "
              "of disturbances")
        ok = False
    if not r["f"] > 0.3:
        print(f"FAIL: {name} the stylus does not rest on the skull ({r['f']:.3f} N)")
        ok = False
    # The wall's stored energy at rest: F^2 / (2 K).
    tolerance = 0.01 * r["f"] ** 2 / (2 * k)
    if r["energy"] > tolerance:
        print(f"FAIL: {name} the force did {r['energy']:.3g} J more work on the device than its damper took out "
              f"(allowed {tolerance:.3g} J)")
        ok = False
sys.exit(1 if not ok else 77 if skipped else 0)
