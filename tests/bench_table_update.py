#!/usr/bin/env python3
"""bench/update_benchmarks.py rewrites only the marked block it was asked for.

Runs the script against stub programs (a fake `isotouch` printing a known report) on a copy
of docs/benchmarks.md, and checks from the file it wrote: the block holds the stub's table
and text, the header names the command and the load, every byte outside the block is as
before; a bench that fails leaves the file byte for byte unchanged; an unknown name and a
missing marker are refused before anything runs.

    tests/bench_table_update.py REPO_ROOT
"""
import os
import shutil
import subprocess
import sys
import tempfile

STUB = """#!/bin/sh
if [ "$STUB_FAIL" = 1 ]; then echo "stub: broken" >&2; exit 3; fi
echo "stub bench: $*"
echo ""
echo "| scene | ms |"
echo "|---|---|"
echo "| head | 12.5 |"
echo "verdict: stub PASS"
"""


def fail(msg):
    print("bench_table_update: FAIL: " + msg)
    sys.exit(1)


def run(root, tmp, doc, *args, env=None):
    e = dict(os.environ, **(env or {}))
    return subprocess.run([sys.executable, os.path.join(root, "bench", "update_benchmarks.py"), "--bin", tmp,
                           "--doc", doc] + list(args), capture_output=True, text=True, env=e)


def outside(text, name):
    b, e = "<!-- bench:%s begin -->" % name, "<!-- bench:%s end -->" % name
    if text.count(b) != 1 or text.count(e) != 1:
        fail("the %s block's markers are not there once each" % name)
    return text[:text.index(b) + len(b)], text[text.index(e):]


def main():
    root = os.path.abspath(sys.argv[1])
    tmp = tempfile.mkdtemp(prefix="bench_table_update.")
    try:
        stub = os.path.join(tmp, "isotouch")
        with open(stub, "w") as f:
            f.write(STUB)
        os.chmod(stub, 0o755)
        doc = os.path.join(tmp, "benchmarks.md")
        shutil.copy(os.path.join(root, "docs", "benchmarks.md"), doc)
        before = open(doc).read()

        p = run(root, tmp, doc, "render")
        if p.returncode != 0:
            fail("the script exited %d: %s" % (p.returncode, p.stderr))
        after = open(doc).read()
        if outside(after, "render") != outside(before, "render"):
            fail("text outside the render block changed")
        inside = after[len(outside(after, "render")[0]):after.index("<!-- bench:render end -->")]
        for want in ("| head | 12.5 |", "verdict: stub PASS", "`isotouch bench render`", "load average before",
                     "stub bench: bench render"):
            if want not in inside:
                fail("the render block lacks %r:\n%s" % (want, inside))
        if "| head | 13.1-17.0 |" in inside:
            fail("the render block still holds the old table")

        p = run(root, tmp, doc, "table1", env={"STUB_FAIL": "1"})
        if p.returncode == 0 or "exited 3" not in p.stderr:
            fail("a failing bench was not reported: rc %d, %s" % (p.returncode, p.stderr))
        if open(doc).read() != after:
            fail("a failing bench changed the file")

        if run(root, tmp, doc, "no-such-bench").returncode != 2:
            fail("an unknown bench name was not refused with exit 2")
        with open(doc, "w") as f:
            f.write(after.replace("<!-- bench:edit end -->", ""))
        p = run(root, tmp, doc, "edit")
        if p.returncode != 1 or "bench:edit end" not in p.stderr:
            fail("a missing end marker was not refused: rc %d, %s" % (p.returncode, p.stderr))
        print("bench_table_update: the render block rewritten, the rest byte for byte as before; "
              "failures leave the file unchanged")
        return 0
    finally:
        shutil.rmtree(tmp)


if __name__ == "__main__":
    sys.exit(main())
