"""Ctrl-C during a long call (an offline render, a pass chain, measure_stroke, cpp_ns_per_tick):
a SIGINT sent from a timer thread to the process raises KeyboardInterrupt long before the
call's end (the time of the whole call, measured here)."""
import os
import subprocess
import sys
import textwrap


def test_ctrl_c_interrupts_a_long_render():
    script = textwrap.dedent("""
        import os, signal, threading, time
        import numpy as np
        import isotouch
        s = isotouch.stroke_scene("sphere", device="cpu")
        p = s.table1_hri_params()
        t0 = time.perf_counter()
        isotouch.render(s.field, s.hip, "hri", p)
        per_tick = (time.perf_counter() - t0) / len(s.hip)
        reps = max(1, int(3.0 / per_tick / (2 * len(s.hip))))  # a call of about 3 s
        hip = np.concatenate([s.hip, s.hip[::-1]] * reps)
        t0 = time.perf_counter()
        isotouch.render(s.field, hip, "hri", p)
        whole = time.perf_counter() - t0
        threading.Timer(0.2, lambda: os.kill(os.getpid(), signal.SIGINT)).start()
        t0 = time.perf_counter()
        try:
            isotouch.render(s.field, hip, "hri", p)
            print("finished", whole)
        except KeyboardInterrupt:
            print("interrupted", time.perf_counter() - t0, whole)
    """)
    interrupted_early(script)


def test_ctrl_c_interrupts_a_long_pass_chain():
    """run_passes on the CPU: a chain of many axis sweeps (Gaussians and closings, at least 2 s)
    is stopped within one sweep, not at its end."""
    script = textwrap.dedent("""
        import os, signal, threading, time
        import numpy as np
        import isotouch
        rng = np.random.default_rng(1)
        v = isotouch.Volume(rng.random((96, 96, 96), dtype=np.float32), spacing=(1e-3,) * 3)
        one = [isotouch.Pass.gaussian(1.5), isotouch.Pass.closing(2.0)]
        reps, whole = 1, 0.0
        while whole < 2.0 and reps <= 4096:  # a chain of at least 2 s, however fast this machine is now
            reps *= 2
            chain = one * reps + [isotouch.Pass.gradient()]
            t0 = time.perf_counter()
            isotouch.run_passes(v, chain)
            whole = time.perf_counter() - t0
        threading.Timer(0.2, lambda: os.kill(os.getpid(), signal.SIGINT)).start()
        t0 = time.perf_counter()
        try:
            isotouch.run_passes(v, chain)
            print("finished", whole)
        except KeyboardInterrupt:
            print("interrupted", time.perf_counter() - t0, whole)
    """)
    interrupted_early(script)


def test_ctrl_c_interrupts_a_long_measure_stroke():
    """measure_stroke's timed replays (repetitions doubled until a call takes 2 s) stop between
    two replays, not after the last."""
    script = textwrap.dedent("""
        import os, signal, threading, time
        import isotouch
        s = isotouch.stroke_scene("sphere", device="cpu")
        p = s.table1_hri_params()
        reps, whole = 1, 0.0
        while whole < 2.0 and reps <= 1 << 20:  # a call of at least 2 s, however fast this machine is now
            reps *= 2
            t0 = time.perf_counter()
            isotouch.measure_stroke(s, "hri", p, repetitions=reps)
            whole = time.perf_counter() - t0
        threading.Timer(0.2, lambda: os.kill(os.getpid(), signal.SIGINT)).start()
        t0 = time.perf_counter()
        try:
            isotouch.measure_stroke(s, "hri", p, repetitions=reps)
            print("finished", whole)
        except KeyboardInterrupt:
            print("interrupted", time.perf_counter() - t0, whole)
    """)
    interrupted_early(script)


def test_ctrl_c_interrupts_a_long_cpp_ns_per_tick():
    """cpp_ns_per_tick's replays (repetitions doubled until a call takes 2 s) stop between two
    replays, not after the last."""
    script = textwrap.dedent("""
        import os, signal, threading, time
        import isotouch
        s = isotouch.stroke_scene("sphere", device="cpu")
        p = s.table1_hri_params()
        reps, whole = 1, 0.0
        while whole < 2.0 and reps <= 1 << 20:  # a call of at least 2 s, however fast this machine is now
            reps *= 2
            t0 = time.perf_counter()
            isotouch.cpp_ns_per_tick(s.field, s.hip, "hri", p, warmup=0, repetitions=reps)
            whole = time.perf_counter() - t0
        threading.Timer(0.2, lambda: os.kill(os.getpid(), signal.SIGINT)).start()
        t0 = time.perf_counter()
        try:
            isotouch.cpp_ns_per_tick(s.field, s.hip, "hri", p, warmup=0, repetitions=reps)
            print("finished", whole)
        except KeyboardInterrupt:
            print("interrupted", time.perf_counter() - t0, whole)
    """)
    interrupted_early(script)


def interrupted_early(script):
    """Runs `script` (which prints 'interrupted TOOK WHOLE' or 'finished WHOLE') in its own
    Python: the SIGINT must have stopped the call in less than half its uninterrupted time."""
    p = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300,
                       env=dict(os.environ))
    assert p.returncode == 0, p.stderr
    words = p.stdout.split()
    assert words[0] == "interrupted", p.stdout
    took, whole = float(words[1]), float(words[2])
    assert whole > 1.0, f"the whole call took {whole:.2f} s: too short to show anything"
    assert took < whole / 2, f"KeyboardInterrupt after {took:.2f} s of a {whole:.2f} s call"
