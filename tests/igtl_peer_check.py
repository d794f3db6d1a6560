"""The Force TRANSFORMs tests/igtl_plus_peer received (its log: "stopped T" when its stream
stopped, "force T FX FY FZ" per Force, T in seconds since the client connected), checked as
every `--haptic igtl:` test checks them: while the stylus is in the skull (from `t_from` to
the stop), at least `min_pushing` forces above `above_n` N, each pushing it back out (-x);
none past the scene's 3.3 N (the peer prints 6 digits of a float32: 1e-4 N); once the stream
stopped, the peer holds an exact zero within the stale timeout (3 stream periods) and 100 ms
for a loaded machine, and gets nothing but zeros after it (the zero may have come before the
stop: a servo stall or ramp-in at that moment).

`python3 igtl_peer_check.py LOG` exits 0 when the last force the peer got before its stream
stopped was not zero (the stylus still in contact: the stale zero is tested), 1 otherwise.
On a loaded machine a stream hiccup of more than 20 ms restarts the renderer with the stylus
inside the bone, which holds no surface: zero force from then on, by design; the tests run
such a scenario once more."""
import sys


def norm(v):
    return sum(c * c for c in v) ** 0.5


def read_log(log_path):
    """(the time the stream stopped, [(t, force)])."""
    peer = open(log_path).read().splitlines()
    stopped = float(next(l.split()[1] for l in peer if l.startswith("stopped ")))
    got = [(float(l.split()[1]), [float(v) for v in l.split()[2:5]]) for l in peer if l.startswith("force ")]
    return stopped, got


def in_contact_at_stop(log_path):
    stopped, got = read_log(log_path)
    before = [f for t, f in got if t < stopped]
    return bool(before) and norm(before[-1]) > 0


def check_peer_forces(log_path, t_from, above_n, min_pushing, rate_hz, fail):
    """Calls fail(message) on the first check that does not hold; returns the forces while
    in the skull, those above above_n, and how long after the stop the peer held zero for
    good [s] (<= 0: from before the stop)."""
    stopped, got = read_log(log_path)
    during = [f for t, f in got if t_from <= t < stopped]
    after = [(t, f) for t, f in got if t >= stopped]
    pushing = [f for f in during if norm(f) > above_n]
    if len(pushing) < min_pushing or len(during) < 500:
        fail(f"{len(pushing)} of {len(during)} forces above {above_n} N at the peer with the stylus in the skull")
    if any(f[0] >= 0 for f in pushing):
        fail("a contact force that does not push the stylus back out (-x)")
    if max(norm(f) for _, f in got) > 3.3 + 1e-4:
        fail("a force past the scene's 3.3 N at the peer")
    zero = [0.0, 0.0, 0.0]
    last_force = max((t for t, f in got if f != zero), default=-1.0)
    held_from = min((t for t, f in got if t > last_force), default=None)  # the first zero of the last run
    if held_from is None:
        fail("the peer holds a force: no zero after the last non-zero one")
    late = held_from - stopped
    if late > 3.0 / rate_hz + 0.1:
        fail(f"the peer held zero for good only {late * 1e3:.1f} ms after the stream stopped (stale timeout "
             f"{3e3 / rate_hz:.1f} ms; its last force other than zero came at {last_force - stopped:+.4f} s)")
    if not after:
        fail("no force came after the stream stopped (not even the zero at close)")
    if late <= 0:
        fail(f"the peer held zero from {-late * 1e3:.1f} ms before the stream stopped (the contact was lost, twice): "
             "the stale zero was not tested")
    return during, pushing, late


if __name__ == "__main__":
    sys.exit(0 if in_contact_at_stop(sys.argv[1]) else 1)
