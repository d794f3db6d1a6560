"""Stops `isotouch run --haptic igtl:` with a signal while tests/igtl_plus_peer holds a contact
force, and checks what the peer got: its last Force is exactly zero, and it arrived within the
stale timeout (3 stream periods) of the signal, widened by the time the machine was measured
to be gone in that interval and by nothing else (tests/sched_canary.py: a canary process per
CPU, each wake-up later than its slack marking [deadline, wake-up] as lost).
The canaries run in the scheduling class of the run and the peer (the default: neither asks
for SCHED_FIFO here), so they lose the CPU when those do: a peer that reads late is timed late.

usage: igtl_signal_check.py PEER_LOG PID SIGNAL RATE_HZ
  PEER_LOG  the peer's output ("clock S": its t = 0 on CLOCK_MONOTONIC; "force T FX FY FZ")
  PID       the isotouch run; SIGNAL INT or TERM; RATE_HZ the peer's stream rate
Waits (10 s at most) for 50 forces above 0.8 N, sends the signal, waits for the run to end.
Prints "signal ok: ..." and exits 0, or "FAIL ..." and exits 1."""
import os
import signal
import sys
import time

from sched_canary import Canaries, lost_in


def forces(log_path):
    """(the peer's t = 0 on CLOCK_MONOTONIC or None, [(t, [fx, fy, fz])])."""
    clock, got = None, []
    for line in open(log_path).read().splitlines():
        w = line.split()
        if w[:1] == ["clock"] and len(w) == 2:
            clock = float(w[1])
        elif w[:1] == ["force"] and len(w) == 5:
            got.append((float(w[1]), [float(v) for v in w[2:5]]))
    return clock, got


def norm(f):
    return sum(c * c for c in f) ** 0.5


def main():
    if len(sys.argv) != 5 or sys.argv[3] not in ("INT", "TERM"):
        print(__doc__)
        return 2
    log, pid, sig, rate = sys.argv[1], int(sys.argv[2]), getattr(signal, "SIG" + sys.argv[3]), float(sys.argv[4])
    fail = lambda msg: (print(f"FAIL haptic igtl: SIG{sys.argv[3]}: {msg}"), 1)[1]
    t_end = time.monotonic() + 10
    while sum(norm(f) > 0.8 for _, f in forces(log)[1]) < 50:
        if time.monotonic() > t_end:
            return fail("the stylus never pushed into the skull (50 forces above 0.8 N) within 10 s")
        time.sleep(0.02)
    canaries = Canaries().start()
    time.sleep(0.05)
    held = forces(log)[1][-1][1]
    t_sig = time.monotonic()
    os.kill(pid, sig)
    while time.monotonic() < t_sig + 10:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.01)
    time.sleep(0.2)  # the peer prints what is still in flight
    lost = canaries.stop()
    clock, got = forces(log)
    if clock is None:
        return fail("the peer printed no clock line")
    if norm(held) == 0:
        return fail("the peer held no force when the signal was sent: the zero is not tested")
    if not got or got[-1][1] != [0.0, 0.0, 0.0]:
        return fail(f"the peer's last Force is {got[-1][1] if got else None}, not an exact zero: it holds a force")
    zero = got[-1][0]
    while zero > 0 and len(got) > 1 and got[-2][1] == [0.0, 0.0, 0.0]:  # the first zero of the last run
        got.pop()
        zero = got[-1][0]
    late = clock + zero - t_sig
    allowed = 3.0 / rate + lost_in(lost, t_sig, clock + zero)
    if late > allowed:
        return fail(f"the zero came {late * 1e3:.1f} ms after the signal, past the stale timeout {3e3 / rate:.1f} ms "
                    f"+ {(allowed - 3.0 / rate) * 1e3:.1f} ms measured lost")
    print(f"signal ok: SIG{sys.argv[3]} with {norm(held):.2f} N held; the zero {late * 1e3:.1f} ms after it "
          f"(allowed {allowed * 1e3:.1f} ms)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
