"""Renders a `study compare` HTML report in headless Chromium and checks that its plots are there.

usage: render_report.py REPORT.html SVG_COUNT [OUT.png]

Chromium (Debian's `chromium`, started headless as the environment requires) takes a full-page
screenshot; the check counts the pixels drawn in the report's two series colours (measured
#1f77b4, model #d62728) in the rendered image, and the <svg> elements of the rendered DOM.
Exits non-zero with a message when a check fails.
"""
import os
import subprocess
import sys
import tempfile

from PIL import Image

report, expected_svgs = os.path.abspath(sys.argv[1]), int(sys.argv[2])
png = os.path.abspath(sys.argv[3]) if len(sys.argv) > 3 else os.path.join(tempfile.mkdtemp(), "report.png")
flags = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--hide-scrollbars"]
with tempfile.TemporaryDirectory() as profile:
    base = ["chromium", *flags, f"--user-data-dir={profile}"]
    dom = subprocess.run([*base, "--dump-dom", "file://" + report], capture_output=True, text=True, timeout=180).stdout
    svgs = dom.count("<svg")
    assert svgs == expected_svgs, f"rendered DOM has {svgs} <svg> plots, expected {expected_svgs}"
    subprocess.run([*base, "--window-size=1000,6000", f"--screenshot={png}", "file://" + report], capture_output=True, timeout=180, check=True)

img = Image.open(png).convert("RGB")
w, h = img.size
assert w >= 900 and h >= 3000, f"screenshot is {w}x{h}"


pixels = img.tobytes()


def count(rgb, tol=40):
    r0, g0, b0 = rgb
    return sum(
        1
        for i in range(0, len(pixels), 3)
        if abs(pixels[i] - r0) < tol and abs(pixels[i + 1] - g0) < tol and abs(pixels[i + 2] - b0) < tol
    )


measured, model = count((31, 119, 180)), count((214, 39, 40))
assert measured > 2000, f"only {measured} pixels of the measured series were drawn"
assert model > 2000, f"only {model} pixels of the model series were drawn"
print(f"{report}: {svgs} plots rendered by Chromium into {png} ({w}x{h}); measured {measured} px, model {model} px")
