#!/usr/bin/env python3
"""Writes the user guide's pictures of isotouch-sculpt (docs/images/sculpt-*-slices.png): the
shipped head, the chest's DICOM folder and the head exported to .vdb, each opened without
--iso, the probe steered onto the surface by a script on the simulated clock.

Each picture is the window as the X server shows it: its own Xvfb, whose framebuffer file
(-fbdir, XWD) holds the 3-D view, the slice views and the panels (the app's --screenshot
holds the picture and the slice views, not the panels); it is read here while the window
is open and written as PNG (zlib, standard library only).

Usage: tools/docs_screenshots.py BUILD_DIR [OUT_DIR]   (OUT_DIR: docs/images)
"""
import os, shutil, signal, struct, subprocess, sys, tempfile, time, zlib

build = os.path.abspath(sys.argv[1])
src = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
out = os.path.abspath(sys.argv[2]) if len(sys.argv) > 2 else os.path.join(src, "docs", "images")
sculpt, isotouch = os.path.join(build, "bin", "isotouch-sculpt"), os.path.join(build, "bin", "isotouch")
W, H = 800, 600


def xwd_rgb(path, w, h):
    """The top-left w x h pixels of a 24-bit TrueColor XWD file (Xvfb's framebuffer) as RGB rows."""
    data = open(path, "rb").read()
    f = struct.unpack(">25I", data[:100])
    header_size, bpp, bytes_per_line, ncolors = f[0], f[11], f[12], f[19]
    assert bpp == 32 and f[7] == 0, "32-bit LSB-first pixels expected"
    base = header_size + 12 * ncolors
    rows = []
    for y in range(h):
        line = data[base + y * bytes_per_line:base + y * bytes_per_line + 4 * w]
        rows.append(b"".join(bytes((line[i + 2], line[i + 1], line[i])) for i in range(0, len(line), 4)))
    return rows


def write_png(path, w, h, rows):
    chunk = lambda kind, body: struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))
    raw = b"".join(b"\x01" + bytes((r[i] - (r[i - 3] if i >= 3 else 0)) & 255 for i in range(len(r))) for r in rows)
    png = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)) +
           chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))
    open(path, "wb").write(png)


def shoot(tag, volume, cursor):
    """The window on `volume` after the probe came to rest on the surface under `cursor`."""
    tmp = tempfile.mkdtemp()
    script = os.path.join(tmp, "script.json")
    open(script, "w").write('{"events": [{"after_frames": 2, "cursor": [%g, %g]}, {"wait": "contact", "timeout_s": 20}]}'
                            % cursor)
    display = ":%d" % (90 + os.getpid() % 100)
    xvfb = subprocess.Popen(["Xvfb", display, "-screen", "0", "1024x768x24", "-fbdir", tmp, "-nolisten", "tcp"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        time.sleep(1.5)
        log = open(os.path.join(tmp, "log.txt"), "w")
        app = subprocess.Popen([sculpt, volume, "--size", str(W), "--sim-clock", "--script", script],
                               env=dict(os.environ, DISPLAY=display), stdout=log, stderr=subprocess.STDOUT)
        time.sleep(float(os.environ.get("SHOT_WAIT_S", "25")))  # frames on the simulated clock, the probe at rest
        shutil.copy(os.path.join(tmp, "Xvfb_screen0"), os.path.join(tmp, "frame.xwd"))
        app.send_signal(signal.SIGTERM)
        app.wait(timeout=60)
        print(open(os.path.join(tmp, "log.txt")).read())
        path = os.path.join(out, f"sculpt-{tag}-slices.png")
        write_png(path, W, H, xwd_rgb(os.path.join(tmp, "frame.xwd"), W, H))
        print(f"wrote {path} ({os.path.getsize(path)} bytes)")
    finally:
        xvfb.terminate()
        xvfb.wait()
        shutil.rmtree(tmp, ignore_errors=True)


head = os.path.join(src, "data", "ct-head-headsq", "headsq_64x64x93_int16.mhd")
vdb = os.path.join(tempfile.mkdtemp(), "head.vdb")
subprocess.run([isotouch, "export", head, "--vdb", vdb], check=True)  # no --iso: the head's own, stored
shoot("head", head, (0.56, 0.6))
shoot("chest-dicom", os.path.join(src, "data", "ct-chest-lungdx-a0001", "dicom-5mm"), (0.36, 0.5))
shoot("head-vdb", vdb, (0.56, 0.6))
