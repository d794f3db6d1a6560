#!/usr/bin/env python3
"""Run the benches and rewrite their marked blocks in docs/benchmarks.md.

A block is the text between `<!-- bench:NAME begin -->` and `<!-- bench:NAME end -->`; it is
replaced by the machine, the date (UTC), the load average before and after, the commit, the
command, and the bench's report (its tables as markdown tables, every other line in a text
block). Text outside the blocks is never touched. The file is rewritten only when every bench
asked for ran and exited 0, and atomically (a temporary file renamed over it).

    bench/update_benchmarks.py [NAME ...] [--bin DIR] [--doc FILE] [--list]
"""
import argparse
import datetime
import os
import re
import shutil
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEFAULT_BIN = os.path.join(ROOT, "build", "bin")

# name -> (program in --bin, arguments, needs a display, lines kept (None: all)). A program
# ending in .py is a script of this repository run by this interpreter, with the module built
# beside --bin (BIN/../python) on PYTHONPATH.
BENCHES = {
    "table1": ("isotouch", ["bench", "table1"], False, None),
    "servo-rt": ("isotouch", ["bench", "servo-rt"], False, None),
    "engine": ("isotouch", ["bench", "engine", "--cases", "head", "chest", "--repetitions", "5"], False, None),
    "edit": ("isotouch", ["bench", "edit"], False, None),
    "render": ("isotouch", ["bench", "render"], False, None),
    "device": ("isotouch", ["bench", "device"], False, None),
    "serve": ("isotouch", ["bench", "serve"], False, None),
    "sculpt-head": ("isotouch-sculpt", ["scenes/head.json", "--bench"], True, r"^(stats|verdict|device|link)"),
    "sculpt-chest": ("isotouch-sculpt", ["scenes/chest.json", "--bench"], True, r"^(stats|verdict|device|link)"),
    "sweep": ("python/bench_sweep.py", [], False, None),
}


def marker(name, end):
    return "<!-- bench:%s %s -->" % (name, "end" if end else "begin")


def block_span(text, name):
    """(start, end) of the block's inside, or an error message."""
    b, e = marker(name, False), marker(name, True)
    if text.count(b) != 1 or text.count(e) != 1:
        return None, "needs exactly one %s and one %s" % (b, e)
    start = text.index(b) + len(b)
    end = text.index(e)
    if end < start:
        return None, "%s comes before %s" % (e, b)
    return (start, end), None


def machine():
    model, cpus, mem = "unknown CPU", 0, ""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name") and model == "unknown CPU":
                    model = line.split(":", 1)[1].strip()
                if line.startswith("processor"):
                    cpus += 1
        with open("/proc/meminfo") as f:
            kib = int(f.readline().split()[1])
            mem = ", %.0f GiB memory" % (kib / 2**20)
    except OSError:
        pass
    return "%s, %d CPUs%s" % (model, cpus or os.cpu_count() or 0, mem)


def loadavg():
    try:
        with open("/proc/loadavg") as f:
            return ", ".join(f.read().split()[:3])
    except OSError:
        return "unknown"


def commit():
    try:
        head = subprocess.run(["git", "-C", ROOT, "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", ROOT, "status", "--porcelain", "--untracked-files=no", "--",
                                ".", ":!docs/benchmarks.md"], capture_output=True, text=True).stdout.strip()
        return head + (" with local changes" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def to_markdown(report, keep):
    """Tables stay tables; runs of other lines go into ```text blocks."""
    lines = [l.rstrip() for l in report.splitlines()]
    if keep:
        lines = [l for l in lines if re.match(keep, l)]
    out, text = [], []

    def flush():
        while text and not text[-1]:
            text.pop()
        while text and not text[0]:
            text.pop(0)
        if text:
            out.extend(["", "```text"] + text + ["```"])
        text.clear()

    in_table = False
    for line in lines:
        if line.startswith("|"):
            if not in_table:
                flush()
                out.append("")
            out.append(line)
            in_table = True
        else:
            in_table = False
            text.append(line)
    flush()
    return "\n".join(out).lstrip("\n")


def module_python(bindir):
    """The interpreter the isotouch module beside BIN was built for (BIN/../python/isotouch/
    _build.py), else this one."""
    try:
        with open(os.path.join(os.path.dirname(os.path.abspath(bindir)), "python", "isotouch", "_build.py")) as f:
            m = re.search(r"^PYTHON = '(.*)'$", f.read(), re.M)
        if m and os.access(m.group(1), os.X_OK):
            return m.group(1)
    except OSError:
        pass
    return sys.executable


def command(name, bindir):
    prog, args, display, _ = BENCHES[name]
    if prog.endswith(".py"):
        argv = [module_python(bindir), os.path.join(ROOT, prog)] + args
    else:
        argv = [os.path.join(bindir, prog)] + args
    if display and not os.environ.get("DISPLAY"):
        if not shutil.which("xvfb-run"):
            return None, "needs a display: set DISPLAY or install xvfb-run"
        argv = ["xvfb-run", "-a", "-s", "-screen 0 1280x1024x24"] + argv
    return argv, None


def run_bench(name, bindir):
    """The block's new inside, or raises RuntimeError naming the bench."""
    argv, err = command(name, bindir)
    if err:
        raise RuntimeError("%s: %s" % (name, err))
    prog, args, _, keep = BENCHES[name]
    t0, load0 = datetime.datetime.now(datetime.timezone.utc), loadavg()
    print("update_benchmarks: running %s: %s" % (name, " ".join(argv)), file=sys.stderr, flush=True)
    try:
        env = dict(os.environ)
        if prog.endswith(".py"):
            pp = os.path.join(os.path.dirname(os.path.abspath(bindir)), "python")
            env["PYTHONPATH"] = pp + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        p = subprocess.run(argv, cwd=ROOT, capture_output=True, text=True, env=env)
    except OSError as e:
        raise RuntimeError("%s: cannot run %s: %s" % (name, argv[0], e))
    t1, load1 = datetime.datetime.now(datetime.timezone.utc), loadavg()
    if p.returncode != 0:
        tail = "\n".join(p.stderr.splitlines()[-5:])
        raise RuntimeError("%s: %s exited %d\n%s" % (name, " ".join(argv), p.returncode, tail))
    span = t0.strftime("%Y-%m-%d %H:%M") + ("" if t1.strftime("%H:%M") == t0.strftime("%H:%M") else
                                              t1.strftime("-%H:%M"))
    built = "commit %s" % commit() if os.path.abspath(bindir) == DEFAULT_BIN else "programs from %s" % bindir
    head = ("%s UTC; %s; load average before %s, after %s; %s;\n`%s`"
            % (span, machine(), load0, load1, built, " ".join([prog] + args)))
    return "\n" + head + "\n\n" + to_markdown(p.stdout, keep) + "\n"


def write_atomic(path, text):
    d = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=".benchmarks.", dir=d)
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("names", nargs="*", help="blocks to refresh (default: all): " + ", ".join(BENCHES))
    ap.add_argument("--bin", default=DEFAULT_BIN, help="folder of the built programs")
    ap.add_argument("--doc", default=os.path.join(ROOT, "docs", "benchmarks.md"), help="the file to rewrite")
    ap.add_argument("--list", action="store_true", help="print the names and their commands, run nothing")
    a = ap.parse_args()
    if a.list:
        for n, (prog, args, _, _) in BENCHES.items():
            print("%-13s %s" % (n, " ".join([prog] + args)))
        return 0
    names = a.names or list(BENCHES)
    unknown = [n for n in names if n not in BENCHES]
    if unknown:
        print("update_benchmarks: unknown bench %s (known: %s)" % (", ".join(unknown), ", ".join(BENCHES)),
              file=sys.stderr)
        return 2
    try:
        with open(a.doc) as f:
            text = f.read()
    except OSError as e:
        print("update_benchmarks: %s: %s" % (a.doc, e), file=sys.stderr)
        return 1
    for n in names:  # every marker checked before anything runs
        if block_span(text, n)[1]:
            print("update_benchmarks: %s: block %s %s" % (a.doc, n, block_span(text, n)[1]), file=sys.stderr)
            return 1
    try:
        blocks = {n: run_bench(n, a.bin) for n in names}
    except RuntimeError as e:
        print("update_benchmarks: %s; %s left unchanged" % (e, a.doc), file=sys.stderr)
        return 1
    for n in names:
        (s, e), _ = block_span(text, n)
        text = text[:s] + blocks[n] + text[e:]
    write_atomic(a.doc, text)
    print("update_benchmarks: rewrote %s in %s" % (", ".join(names), a.doc), file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
