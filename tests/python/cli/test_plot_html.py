"""plot --html: one self-contained interactive file of the surface and the volume view, opened in
headless Chromium (Debian's chromium, installed by tools/setup): the page draws (the screenshot
is not blank, in both halves) and raises no error (window errors and console.error, caught by a
probe script put in front of the page's own)."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess

import numpy as np
import pytest

from helpers import PARAMS, machine_path, run_cli

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
needs_chromium = pytest.mark.skipif(CHROMIUM is None, reason="no chromium (tools/setup installs Debian's chromium)")

PROBE = """<script>
window.__errors = [];
window.addEventListener("error", e => window.__errors.push("error: " + e.message));
window.addEventListener("unhandledrejection", e => window.__errors.push("rejection: " + e.reason));
const __consoleError = console.error;
console.error = (...a) => { window.__errors.push("console.error: " + a.join(" ")); __consoleError(...a); };
window.addEventListener("load", () => setTimeout(() => {
  const gd = document.querySelector(".plotly-graph-div");
  const pre = document.createElement("pre");
  pre.id = "probe";
  pre.textContent = JSON.stringify({errors: window.__errors, traces: gd && gd.data ? gd.data.length : -1,
                                    canvases: document.querySelectorAll("canvas").length,
                                    text: document.body.innerText});
  document.body.appendChild(pre);
}, 2000));
</script>"""


@pytest.fixture(scope="module")
def html(tmp_path_factory):
    out = tmp_path_factory.mktemp("html") / "five_axis_ac.html"
    proc = run_cli("plot", machine_path("five_axis_ac"), "--params", os.path.join(PARAMS, "five_axis_ac-demo.yaml"),
                   "--over", "X,Cp", "--set", "Ap=30", "--grid", "21", "--html", str(out))
    assert f"wrote {out}" in proc.stderr and "plot.png" not in proc.stderr   # --html alone: no PNG
    return out


def _chromium(tmp_path, *args):
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader",
           "--enable-unsafe-swiftshader", "--disable-dev-shm-usage", "--no-first-run",
           f"--user-data-dir={tmp_path / 'profile'}", "--window-size=1280,800", "--virtual-time-budget=15000",
           *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=180)


@pytest.mark.slow
def test_the_file_is_self_contained(html):
    text = html.read_text(encoding="utf-8")
    assert len(text) > 1_000_000                                      # plotly.js inside
    assert not re.search(r"<script[^>]+src=", text)                   # nothing fetched: works offline
    for label in ("dy [µm]", "|tool point error| [µm]", "five_axis_ac", "held: Y = 0 mm, Z = 0 mm, Ap = 30 deg",
                  "tool point x [mm]", "X [mm]", "Cp [deg]"):
        assert label in text or json.dumps(label)[1:-1] in text, label


@needs_chromium
def test_chromium_draws_it_without_errors(html, tmp_path):
    probe = tmp_path / "probe.html"
    probe.write_text(html.read_text(encoding="utf-8").replace("<head>", "<head>" + PROBE, 1), encoding="utf-8")
    proc = _chromium(tmp_path, "--dump-dom", probe.as_uri())
    found = re.search(r'<pre id="probe">(.*?)</pre>', proc.stdout, re.S)
    assert found, proc.stderr[-2000:]
    report = json.loads(found.group(1).replace("&lt;", "<").replace("&gt;", ">").replace("&amp;", "&"))
    assert report["errors"] == []
    assert report["traces"] == 4            # surface, arrows, their tips, the key
    assert report["canvases"] >= 2          # the two WebGL scenes
    assert "WebGL is not supported" not in report["text"]


@needs_chromium
def test_the_screenshot_is_not_blank(html, tmp_path):
    from PIL import Image
    shot = tmp_path / "shot.png"
    proc = _chromium(tmp_path, f"--screenshot={shot}", html.as_uri())
    assert shot.exists(), proc.stderr[-2000:]
    gray = np.asarray(Image.open(shot).convert("L"), float)
    assert gray.shape == (800, 1280)
    for half in (gray[:, :640], gray[:, 640:]):          # the surface, the volume
        assert half.std() > 10.0
        assert (half < 200).mean() > 0.05                 # well beyond the titles' text
    # the surface's colours, not only grey axes: a viridis surface has saturated pixels
    rgb = np.asarray(Image.open(shot).convert("RGB"), float)[:, :640]
    assert ((rgb.max(axis=2) - rgb.min(axis=2)) > 80).mean() > 0.02
