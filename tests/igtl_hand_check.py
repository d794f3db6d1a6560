"""Judge igtl_hand_peer's logs (cli_haptic_igtl_delay.sh): the device's own motion and energy.
Usage: igtl_hand_check.py PLAIN_PEER_LOG CONTROLLED_PEER_LOG"""
import sys


def read(path):
    ticks, energy, pc, still = [], None, None, None
    for line in open(path):
        w = line.split()
        if w[:1] == ["still"]:
            still = float(w[1])
        elif w[:1] == ["tick"]:
            ticks.append((float(w[1]), float(w[2]), float(w[3])))
        elif w[:1] == ["energy"]:
            energy = float(w[1])
        elif w[:1] == ["pc"]:
            pc = (int(w[1]), float(w[2]))
    if energy is None or still is None or len(ticks) < 1000:
        print(f"FAIL {path}: the peer's run did not finish ({len(ticks)} ticks)")
        sys.exit(1)
    return ticks, energy, pc, still


def judge(path):
    """(contact time [s], the oscillation's amplitude (the largest half peak-to-peak within
    100 ms) from 200 ms after the contact and the hand's stop, whichever is later [mm],
    mean depth and force over the last 0.5 s, energy [J], (controller's active ticks, its
    dissipated energy [J]))."""
    ticks, energy, pc, still = read(path)
    contact = next((t for t, _, f in ticks if f > 0.05), None)
    if contact is None:
        print(f"FAIL {path}: the stylus never touched the skull (largest force {max(f for _, _, f in ticks):.3f} N)")
        sys.exit(1)
    # A fixed window, 2.5 s from 200 ms after the contact and the hand's stop: the run's stop
    # (its force ramped off, the hand then pushing the stylus in) comes later, its live part
    # lasting 6.3 s from after its 1 s rate measurement, both counted from the connection.
    since = max(contact, still) + 0.2
    end = since + 2.5
    if ticks[-1][0] < end + 0.5:
        print(f"FAIL {path}: the run ended at {ticks[-1][0]:.3f} s, before the judged window's end {end:.3f} s + 0.5 s")
        sys.exit(1)
    settled = [s for t, s, _ in ticks if since <= t <= end]
    if len(settled) < 1000:
        print(f"FAIL {path}: only {len(settled)} ticks from 200 ms after contact")
        sys.exit(1)
    # The oscillation's amplitude: the largest half peak-to-peak within any 100 ms (the wall's
    # mode at K 800 N/m and 80 g is about 16 Hz: a period fits), not the slow creep of a
    # damped stylus settling into its rest over seconds.
    w = 100
    amplitude = max(0.5 * (max(settled[i:i + w]) - min(settled[i:i + w])) for i in range(0, len(settled) - w + 1, 10))
    last = [(s, f) for t, s, f in ticks if end - 0.5 <= t <= end]
    mean_s = sum(s for s, _ in last) / len(last)
    mean_f = sum(f for _, f in last) / len(last)
    return contact, amplitude, mean_s, mean_f, energy, pc, since, end


plain = judge(sys.argv[1])
controlled = judge(sys.argv[2])
k = 800.0
for name, (contact, amp, s, f, e, pc, since, end) in (("without controller", plain), ("with controller", controlled)):
    print(f"{name}: contact at {contact:.3f} s, oscillation {amp:.4f} mm (half peak-to-peak within 100 ms) "
          f"(from {since:.3f} s to {end:.3f} s), resting {s:.2f} mm in with {f:.3f} N, device energy out {e:.3g} J, controller active {pc[0]} ticks "
          f"({pc[1]:.3g} J)")
ok = True
if plain[1] <= 0.5:
    print(f"FAIL: without the controller the press settled ({plain[1]:.4f} mm): the test shows nothing")
    ok = False
if controlled[1] >= 0.1:
    print(f"FAIL: with the controller at the device end the stylus still moves {controlled[1]:.4f} mm (>= 0.1 mm)")
    ok = False
if not controlled[3] > 0.3:
    print(f"FAIL: with the controller the stylus does not rest on the skull ({controlled[3]:.3f} N)")
    ok = False
# The wall's stored energy at rest: F^2 / (2 K).
tolerance = 0.01 * controlled[3] ** 2 / (2 * k)
if controlled[4] > tolerance:
    print(f"FAIL: with the controller the force did {controlled[4]:.3g} J more work on the device than its damper "
          f"took out (allowed {tolerance:.3g} J)")
    ok = False
sys.exit(0 if ok else 1)
