"""How long the machine was gone, measured beside a wall-clock test run by a script (as
tests/sched_canary.h does inside a C++ test): a canary process per CPU wakes every PERIOD_S at
absolute deadlines; a wake-up later than SLACK_S marks [deadline, wake-up] as lost. The
canaries run in the default scheduling class, as the programs under test do here, so they lose
the CPU when those do: a test widens a wall-clock bound by lost_in() over the interval it
bounds, and by nothing else (igtl_signal_check.py)."""
import multiprocessing as mp
import os
import signal
import time

PERIOD_S, SLACK_S = 0.0005, 0.0003


def canary(cpu, stop, out):
    """Wakes every PERIOD_S on `cpu`; sends each late wake-up's [deadline, wake-up]."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent ends it through `stop`
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    os.sched_setaffinity(0, {cpu})  # the default scheduler, as the programs under test: it loses what they lose
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


class Canaries:
    """One canary per CPU of this process's affinity, from start() to stop() (-> intervals)."""

    def __init__(self):
        self.stop_event, self.out = mp.Event(), mp.Queue()
        self.procs = [mp.Process(target=canary, args=(c, self.stop_event, self.out))
                      for c in sorted(os.sched_getaffinity(0))]

    def start(self):
        for p in self.procs:
            p.start()
        return self

    def stop(self):
        self.stop_event.set()
        lost = [iv for _ in self.procs for iv in self.out.get()]
        for p in self.procs:
            p.join()
        return lost
