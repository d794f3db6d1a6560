"""Stops `isotouch run --haptic igtl:` with a signal while tests/igtl_plus_peer holds a contact
force, and checks what the peer got: its last Force is exactly zero, and it arrived within the
stale timeout (3 stream periods) of the signal, widened by the time the machine was measured
to be gone in that interval and by nothing else (a canary process per CPU, as
tests/sched_canary.h: each wake-up later than its slack marks [deadline, wake-up] as lost).
The canaries run in the scheduling class of the run and the peer (the default: neither asks
for SCHED_FIFO here), so they lose the CPU when those do: a peer that reads late is timed late.

usage: igtl_signal_check.py PEER_LOG PID SIGNAL RATE_HZ
  PEER_LOG  the peer's output ("clock S": its t = 0 on CLOCK_MONOTONIC; "force T FX FY FZ")
  PID       the isotouch run; SIGNAL INT or TERM; RATE_HZ the peer's stream rate
Waits (10 s at most) for 50 forces above 0.8 N, sends the signal, waits for the run to end.
Prints "signal ok: ..." and exits 0, or "FAIL ..." and exits 1."""
import multiprocessing as mp
import os
import signal
import sys
import time

PERIOD_S, SLACK_S = 0.0005, 0.0003


def canary(cpu, stop, out):
    """Wakes every PERIOD_S on `cpu`; sends each late wake-up's [deadline, wake-up]."""
    os.sched_setaffinity(0, {cpu})  # the default scheduler, as the run and the peer: it loses what they lose
    lost, deadline = [], time.monotonic()
    while not stop.is_set():
        deadline += PERIOD_S
        delay = deadline - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        woke = time.monotonic()
        if woke - deadline > SLACK_S:
            lost.append((deadline, woke))
            deadline = woke
    out.put(lost)


def lost_in(intervals, t0, t1):
    """Seconds of [t0, t1] that some CPU's canary marked lost (the CPUs' losses merged)."""
    cut = sorted((max(a, t0), min(b, t1)) for a, b in intervals if b > t0 and a < t1)
    total, end = 0.0, t0
    for a, b in cut:
        a = max(a, end)
        if b > a:
            total, end = total + b - a, b
    return total


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
    stop, out = mp.Event(), mp.Queue()
    cpus = sorted(os.sched_getaffinity(0))
    canaries = [mp.Process(target=canary, args=(c, stop, out)) for c in cpus]
    for c in canaries:
        c.start()
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
    stop.set()
    lost = [iv for _ in canaries for iv in out.get()]
    for c in canaries:
        c.join()
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
