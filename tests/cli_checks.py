"""What the Python CLI tests share: a check that prints ok / FAIL and remembers failures, and
the last line ctest matches ("PASS NAME" or "FAIL NAME: ...") with the exit status."""
import sys


class Checks:
    def __init__(self):
        self.failures = []

    def __call__(self, ok, what):
        print(("ok   " if ok else "FAIL ") + what)
        if not ok:
            self.failures.append(what)

    def finish(self, name):
        print(f"FAIL {name}: " + "; ".join(self.failures) if self.failures else f"PASS {name}")
        sys.exit(1 if self.failures else 0)
