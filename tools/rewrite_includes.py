#!/usr/bin/env python3
"""Rewrite the project's own #include "name.h" lines to the "isotouch/<folder>/name.h" form.

Why: installed headers live under PREFIX/include/isotouch/<folder>/, and a consumer's include
path gets only PREFIX/include, so bare names such as "scene.h" or "volume.h" never reach it.
The build tree sees the same paths through BUILD_DIR/include/isotouch -> the source root.
Idempotent: run it after merging branches written in the older form.
Usage: tools/rewrite_includes.py [ROOT]   (default: the repository this script is in)
"""
import os
import pathlib
import re
import subprocess
import sys

ROOT = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else pathlib.Path(__file__).resolve().parents[1])
INCLUDE = re.compile(r'^(\s*#\s*include\s+)"([^"]+)"', re.M)


def tracked(*patterns):
    out = subprocess.run(["git", "-C", str(ROOT), "ls-files", *patterns], check=True,
                         capture_output=True, text=True).stdout.split()
    return [pathlib.PurePosixPath(p) for p in out]


def main():
    headers = tracked("*.h")
    by_name = {}
    for h in headers:
        by_name.setdefault(h.name, []).append(h)
    known = set(headers)
    changed = 0
    for src in tracked("*.h", "*.cpp", "*.cc", "*.in"):
        if src.parts[0] in ("build", "tools"):
            continue
        path = ROOT / src
        text = path.read_text()

        def fix(m):
            name = m.group(2)
            if name.startswith("isotouch/"):
                return m.group(0)
            rel = pathlib.PurePosixPath(name)
            here = pathlib.PurePosixPath(os.path.normpath(src.parent / rel))
            candidates = [here] if here in known else []
            if not candidates and rel in known:
                candidates = [rel]
            if not candidates and "/" not in name and len(by_name.get(name, [])) == 1:
                candidates = by_name[name]
            if not candidates:
                return m.group(0)  # system, third-party or generated header
            return f'{m.group(1)}"isotouch/{candidates[0]}"'

        new = INCLUDE.sub(fix, text)
        if new != text:
            path.write_text(new)
            changed += 1
    print(f"rewrote includes in {changed} files")


if __name__ == "__main__":
    main()
