#!/usr/bin/env python3
"""Every relative link in README.md and docs/*.md resolves, README.md stays short, and
the README's commands (`isotouch ...`) come after its line that puts build/bin on the PATH.

A link [text](target) or image ![alt](target) outside code is checked when its target is
relative: the file or folder must exist (relative to the linking file), and a #anchor must
name a heading of the target markdown file (GitHub's slugs). Web links are not fetched.
Prints one line per broken link (file:line: target: why) and exits 1 if there is any.

    tests/docs_links.py REPO_ROOT
"""
import glob
import os
import re
import sys

README_MAX_LINES = 250
LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]*)>?(?:\s+\"[^\"]*\")?\s*\)")
REF_DEF = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s+\".*\")?\s*$")
HEADING = re.compile(r"^\s{0,3}(#{1,6})\s+(.*?)\s*#*\s*$")


def strip_code(lines, inline=True):
    """Lines with fenced blocks blanked and (inline) code spans removed: links there are examples."""
    out, fence = [], None
    for line in lines:
        m = re.match(r"^\s{0,3}(`{3,}|~{3,})", line)
        if fence:
            if m and m.group(1)[0] == fence[0] and len(m.group(1)) >= len(fence):
                fence = None
            out.append("")
            continue
        if m:
            fence = m.group(1)
            out.append("")
            continue
        out.append(re.sub(r"(`+).*?\1", "", line) if inline else line)
    return out


def slug(heading):
    """GitHub's anchor for a heading: links and code marks dropped, lower case, punctuation
    other than '-' and '_' removed, spaces to '-'."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)
    text = text.lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path, cache={}):
    if path not in cache:
        with open(path, encoding="utf-8") as f:
            lines = strip_code(f.read().splitlines(), inline=False)
        seen, found = {}, set()
        for line in lines:
            m = HEADING.match(line)
            if not m:
                continue
            s = slug(m.group(2))
            n = seen.get(s, 0)
            seen[s] = n + 1
            found.add(s if n == 0 else "%s-%d" % (s, n))
        for m in re.finditer(r"<a\s+(?:name|id)=\"([^\"]+)\"", "\n".join(lines)):
            found.add(m.group(1))
        cache[path] = found
    return cache[path]


def check_target(src, target):
    """'' if the target resolves, else why not."""
    if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I):  # http:, https:, mailto:
        return ""
    path, _, anchor = target.partition("#")
    dest = src if not path else os.path.normpath(os.path.join(os.path.dirname(src), path))
    if not os.path.exists(dest):
        return "no such file or folder %s" % os.path.relpath(dest)
    if anchor:
        if not dest.endswith(".md") or os.path.isdir(dest):
            return "an anchor into a file that is not markdown"
        if anchor not in anchors(dest):
            return "no heading with anchor #%s in %s" % (anchor, os.path.relpath(dest))
    return ""


def check_file(path):
    with open(path, encoding="utf-8") as f:
        lines = strip_code(f.read().splitlines())
    errors = []
    for i, line in enumerate(lines, 1):
        targets = [m.group(1) for m in LINK.finditer(line)]
        m = REF_DEF.match(line)
        if m:
            targets.append(m.group(1))
        for t in targets:
            if not t:
                errors.append("%s:%d: empty link target" % (path, i))
                continue
            why = check_target(path, t)
            if why:
                errors.append("%s:%d: %s: %s" % (path, i, t, why))
    return errors


PATH_LINE = "export PATH=$PWD/build/bin:$PATH"
PROGRAM = re.compile(r"(^|[\s`&|;(])isotouch(-sculpt|-devemu)? ")


def readme_commands_on_path(lines):
    """The README's commands name the programs plainly (`isotouch run ...`): each command,
    a code block's line or a table's last cell, must come after the line that puts
    build/bin on the PATH."""
    errors = []
    path_at = next((i for i, l in enumerate(lines, 1) if l.strip() == PATH_LINE), None)
    in_code = False
    for i, line in enumerate(lines, 1):
        if line.startswith("```"):
            in_code = not in_code
            continue
        command = line if in_code else (line.rstrip().rstrip("|").rsplit("|", 1)[-1] if line.startswith("|") else "")
        if not PROGRAM.search(command.split("#")[0]):
            continue
        if path_at is None or i < path_at:
            errors.append("README.md:%d: '%s' runs before build/bin is on the PATH (%s)" % (i, line.strip()[:60], PATH_LINE))
    return errors


def main():
    root = os.path.abspath(sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), ".."))
    os.chdir(root)
    files = ["README.md"] + sorted(glob.glob("docs/**/*.md", recursive=True))
    errors = []
    for f in files:
        errors += check_file(f)
    with open("README.md", encoding="utf-8") as f:
        n = len(f.read().splitlines())
    with open("README.md", encoding="utf-8") as f:
        errors += readme_commands_on_path(f.read().splitlines())
    if n > README_MAX_LINES:
        errors.append("README.md: %d lines, more than %d: move the details into docs/" % (n, README_MAX_LINES))
    for e in errors:
        print(e)
    links = sum(len(LINK.findall("\n".join(strip_code(open(f, encoding="utf-8").read().splitlines()))))
                for f in files)
    print("docs_links: %d files, %d links, %d problems; README.md %d lines" % (len(files), links, len(errors), n))
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
