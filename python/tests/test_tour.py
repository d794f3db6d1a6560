"""docs/python.md's tour, run as written: its code blocks in order, in a folder that sees the
source tree's data/ and scenes/; it must print and draw what the page shows."""
import os
import re
import subprocess
import sys

PNG = b"\x89PNG\r\n\x1a\n"


def tour_code(root):
    text = (root / "docs/python.md").read_text(encoding="utf-8")
    tour = text.split("## A tour", 1)[1].split("\n## ", 1)[0]
    blocks = re.findall(r"```python\n(.*?)```", tour, re.S)
    assert blocks, "docs/python.md: no python block in the tour"
    return "\n".join(blocks)


def test_tour_runs_and_draws(root, tmp_path):
    for d in ("data", "scenes"):
        os.symlink(root / d, tmp_path / d)
    (tmp_path / "docs/images").mkdir(parents=True)
    p = subprocess.run([sys.executable, "-c", tour_code(root)], cwd=tmp_path, capture_output=True, text=True,
                       timeout=600, env=dict(os.environ))
    assert p.returncode == 0, p.stderr
    assert "(64, 256, 256) float32" in p.stdout
    for name in ("HRI", "Avila-Sobierajski"):
        m = re.search(name + r": (\d+) contact ticks of (\d+), max \|F\| ([\d.]+) N", p.stdout)
        assert m and int(m.group(1)) > 0 and float(m.group(3)) > 0, p.stdout
    png = (tmp_path / "docs/images/python-tour-force.png").read_bytes()
    assert png.startswith(PNG) and len(png) > 10_000
