"""Every figure and HTML page a person reads, opened in headless Chromium at 1280 x 800 (issue
#44 item 3, #45 item 4): no text outside its canvas, no horizontal scroll, and the calibration
report's figures and tables there.

- Each figure (plot's map, surface, volume, replay and table views, budget, ballbar, iso230-2)
  is written as SVG, where matplotlib keeps every text as a group of its own (id text_N);
  Chromium lays it out and a probe script measures each text's box against the figure's.
  The same figures as PNG: a text cut at the canvas' edge leaves ink in its outermost pixels.
- plot --html and identify --report: the page is no wider than the window, and every text
  node's box lies within it horizontally.

Chromium runs offline (file:// only), with a throw-away profile; the probe writes its findings
into the DOM, read back with --dump-dom. Skipped (with the reason) only where chromium is absent;
tools/setup --sanitize installs Debian's chromium for CI."""

from __future__ import annotations

import html
import json
import os
import re
import shutil
import subprocess

import numpy as np
import pytest

from helpers import PARAMS, RUNS, VMC, cli, machine_path

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="no chromium (tools/setup --sanitize installs Debian's "
                                                          "chromium; CI has it)")
WIDTH, HEIGHT = 1280, 800
FIVE, FIVE_PARAMS = machine_path("five_axis_ac"), os.path.join(PARAMS, "five_axis_ac-demo.yaml")

# Each figure's boxes: the svg's and every text group's (matplotlib: <g id="text_N">), in CSS px.
SVG_PROBE = """<script>
window.addEventListener("load", () => {
  const out = {};
  for (const fig of document.querySelectorAll("div.fig")) {
    const svg = fig.querySelector("svg"), box = svg.getBoundingClientRect();
    const outside = [];
    let texts = 0;
    for (const g of svg.querySelectorAll('g[id^="text_"]')) {
      const r = g.getBoundingClientRect();
      if (r.width === 0 && r.height === 0) continue;
      texts++;
      if (r.left < box.left - 0.5 || r.right > box.right + 0.5 || r.top < box.top - 0.5 || r.bottom > box.bottom + 0.5)
        outside.push([g.id, r.left - box.left, r.right - box.right, r.top - box.top, r.bottom - box.bottom]);
    }
    out[fig.dataset.name] = {texts, outside, width: box.width, height: box.height};
  }
  const pre = document.createElement("pre");
  pre.id = "probe";
  pre.textContent = JSON.stringify(out);
  document.body.appendChild(pre);
});
</script>"""

# A page: its scroll width, and every text node's box (a Range around it) against the window.
PAGE_PROBE = """<script>
window.addEventListener("load", () => setTimeout(() => {
  const outside = [];
  let texts = 0;
  const walker = document.createTreeWalker(document.body, NodeFilter.SHOW_TEXT);
  for (let n = walker.nextNode(); n; n = walker.nextNode()) {
    if (!n.textContent.trim() || n.parentElement.closest("script,style,pre#probe")) continue;
    const range = document.createRange();
    range.selectNodeContents(n);
    for (const r of range.getClientRects()) {
      if (r.width === 0) continue;
      texts++;
      if (r.left + window.scrollX < -0.5 || r.right + window.scrollX > innerWidth + 0.5)
        outside.push([n.textContent.slice(0, 60), r.left, r.right]);
    }
  }
  const pre = document.createElement("pre");
  pre.id = "probe";
  pre.textContent = JSON.stringify({
    scrollWidth: document.documentElement.scrollWidth, innerWidth, texts, outside,
    svgs: [...document.querySelectorAll("figure svg")].map(s => s.getBoundingClientRect().width),
    tables: document.querySelectorAll("table").length, h2: [...document.querySelectorAll("h2")].map(h => h.textContent),
    plotly: document.querySelectorAll(".plotly-graph-div").length});
  document.body.appendChild(pre);
}, 2000));
</script>"""


def _chromium(tmp_path, page) -> dict:
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader",
           "--enable-unsafe-swiftshader", "--disable-dev-shm-usage", "--no-first-run", "--hide-scrollbars",
           f"--user-data-dir={tmp_path / 'profile'}", f"--window-size={WIDTH},{HEIGHT}",
           "--virtual-time-budget=15000", "--dump-dom", page.as_uri()]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
    found = re.search(r'<pre id="probe">(.*?)</pre>', proc.stdout, re.S)
    assert found, proc.stderr[-2000:]
    return json.loads(html.unescape(found.group(1)))


FIGURES = {   # name -> chaincomp arguments before -o/--plot, and that option
    "map": (["plot", FIVE, "--params", FIVE_PARAMS, "--over", "X,Cp", "--set", "Ap=30"], "-o"),
    "surface": (["plot", FIVE, "--params", FIVE_PARAMS, "--view", "surface", "--grid", "21"], "-o"),
    "volume": (["plot", FIVE, "--params", FIVE_PARAMS, "--view", "volume"], "-o"),
    "table": (["plot", FIVE, "--table", os.path.join(PARAMS, "five_axis_ac-laser.yaml"), "--error", "EXX"], "-o"),
    "budget": (["budget", FIVE, "--params", FIVE_PARAMS, "--over", "X,Y,Cp", "--grid", "5"], "--plot"),
    "ballbar": (["ballbar", VMC, "--set", "EXX=1", "--plane", "XY", "--radius", "10"], "--plot"),
    "iso230-2": (["iso230-2", RUNS], "--plot"),
}


@pytest.fixture(scope="module")
def figures(tmp_path_factory):
    """{name: (svg path, png path)} of every figure, the replay's included."""
    tmp = tmp_path_factory.mktemp("figures")
    log, replay = tmp / "axes.lcmlog", tmp / "replay.csv"
    cli("simulate-log", FIVE, "-o", log, "--seconds", "0.1")
    cli("replay", FIVE, log, "--params", FIVE_PARAMS, "--csv", replay)
    cases = dict(FIGURES, replay=(["plot", FIVE, "--params", FIVE_PARAMS, "--replay", replay], "-o"))
    out = {}
    for name, (argv, option) in cases.items():
        out[name] = tuple(tmp / f"{name}.{kind}" for kind in ("svg", "png"))
        for path in out[name]:
            cli(*argv, option, path)
    return out


def test_every_text_of_every_figure_is_inside_its_canvas(figures, tmp_path):
    parts = ["<!DOCTYPE html><html><head><meta charset='utf-8'>", SVG_PROBE, "</head><body style='margin:0'>"]
    for name, (svg, _) in figures.items():
        text = svg.read_text(encoding="utf-8")
        parts.append(f'<div class="fig" data-name="{name}">{text[text.index("<svg"):]}</div>')
    page = tmp_path / "figures.html"
    page.write_text("".join(parts) + "</body></html>", encoding="utf-8")
    found = _chromium(tmp_path, page)
    assert set(found) == set(figures)
    for name, f in found.items():
        assert f["texts"] >= 8, name              # titles, labels and ticks were measured
        assert f["outside"] == [], name


def test_no_png_figure_has_ink_at_its_edge(figures):
    from PIL import Image
    for name, (_, png) in figures.items():
        gray = np.asarray(Image.open(png).convert("L"), float)
        edge = np.concatenate([gray[:3].ravel(), gray[-3:].ravel(), gray[:, :3].ravel(), gray[:, -3:].ravel()])
        assert edge.min() > 200, name             # white margins all round: nothing cut


def _probe_copy(path, tmp_path):
    page = tmp_path / ("probe-" + path.name)
    page.write_text(path.read_text(encoding="utf-8").replace("<head>", "<head>" + PAGE_PROBE, 1), encoding="utf-8")
    return page


def test_the_plot_html_page_fits_a_1280_px_window(tmp_path):
    out = tmp_path / "page.html"
    cli("plot", FIVE, "--params", FIVE_PARAMS, "--over", "X,Cp", "--set", "Ap=30", "--grid", "21", "--html", out)
    found = _chromium(tmp_path, _probe_copy(out, tmp_path))
    assert found["plotly"] == 1
    assert found["scrollWidth"] <= WIDTH == found["innerWidth"]
    assert found["texts"] >= 20 and found["outside"] == []


def test_the_calibration_report_fits_and_has_its_figures_and_tables(tmp_path):
    meas, out = tmp_path / "meas.csv", tmp_path / "report.html"
    machine = machine_path("angle_head")
    cli("simulate-measurements", machine, "--params", os.path.join(PARAMS, "angle_head-fig3.yaml"), "--noise", "1um",
        "--seed", "1", "-o", meas)
    cli("identify", machine, meas, "--assume-zero", "DY,ThetaAv", "--report", out)
    found = _chromium(tmp_path, _probe_copy(out, tmp_path))
    assert found["scrollWidth"] <= WIDTH and found["outside"] == []
    assert found["h2"] == ["Summary", "Set-up", "Plan: 16 poses", "Residual per measurement", "Dispersion per axis",
                           "Identified values", "Correlations", "What these measurements could not see"]
    assert len(found["svgs"]) == 4 and all(100 < w <= WIDTH for w in found["svgs"])   # drawn, within the page
    assert found["tables"] == 7   # summary, set-up, plan, residuals, dispersion, values, not seen
