"""The calibration report (analysis.calibration_report, identify --report): one self-contained
HTML file whose every outside text stays text (read back by Python's own HTML parser), and
whose numbers are those of the measurements: the residual before the fit is the measured point
minus the nominal one (chaincomp eval without errors), after a fit of noiseless data it is nil,
and the values are the params file's. Headless Chromium opens it in test_figures_in_chromium."""

from __future__ import annotations

import csv
import html.parser
import json
import math
import re

import numpy as np
import pytest
import yaml

from helpers import PARAMS, cli, machine_path

from chaincomp.analysis.calibration_report import Calibration, Dispersion, Residual, Value, to_html

HOSTILE = '</td></table><script>alert(1)</script><img src=x onerror=alert(2)> & "q" \x1b[2J'


class _Reader(html.parser.HTMLParser):
    """Tags, attributes and text, as a browser's tokenizer sees them."""

    def __init__(self):
        super().__init__()
        self.tags, self.attrs, self.text = [], [], []

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)
        self.attrs += attrs

    def handle_data(self, data):
        self.text.append(data)


def _read(text: str) -> _Reader:
    r = _Reader()
    r.feed(text)
    r.close()
    return r


def test_outside_text_stays_text_and_nothing_is_fetched():
    c = Calibration("chaincomp identify", HOSTILE, "2026-12-07 20:00 UTC", setup=[("measurements", HOSTILE)],
                    plan_columns=["pose", "X [mm]"], plan=[[HOSTILE, "1"]],
                    residuals=[Residual(HOSTILE, 3.0, 0.5), Residual("line 5", 2.0, 0.25)],
                    dispersion_meaning=HOSTILE, dispersion=[Dispersion("x", 2.0, 0.3)],
                    values=[Value("EXX", 1.5, 0.2, "µm"), Value("EYY", -2.0, 0.3, "µm")],
                    correlation=[[1.0, 0.95], [0.95, 1.0]], not_seen=[("ThetaAv", HOSTILE)],
                    summary=[("set-ups", "2")], warnings=[HOSTILE])
    page = to_html(c)
    r = _read(page)
    assert "script" not in r.tags and "img" not in r.tags
    assert not any(name.startswith("on") for name, _ in r.attrs)
    # each hostile text is there, as text, once per place it was put (escapes shown, not obeyed)
    shown = HOSTILE.replace("\x1b", "\\x1b")
    assert "".join(r.text).count(shown) >= 7
    # self-contained: nothing to fetch (the SVG's glyphs are links inside the page, #id; a colour bar data:)
    links = [v for name, v in r.attrs if name in ("src", "href", "xlink:href", "data")]
    assert links and all(v.startswith(("#", "data:image/png;base64,")) for v in links)
    assert "@import" not in page and not re.search(r"url\((?!#)", page)
    assert page.count("<svg") == 4                          # residuals, dispersion, values, correlation
    assert "EXX/EYY +0.950" in page                         # the correlation above 0.9 named


@pytest.fixture(scope="module")
def noiseless(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("report")
    meas, report = tmp / "m.csv", tmp / "r.html"
    machine, params = machine_path("angle_head"), f"{PARAMS}/angle_head-fig3.yaml"
    cli("simulate-measurements", machine, "--params", params, "--noise", "0", "--seed", "1", "-o", meas)
    proc = cli("identify", machine, meas, "--assume-zero", "DY,ThetaAv", "--sigma", "1um", "--report", report)
    assert f"wrote {report}" in proc.stdout
    return machine, params, meas, report.read_text(encoding="utf-8")


def _table_after(page: str, heading: str) -> list[list[str]]:
    part = page.split(heading, 1)[1].split("<h2>", 1)[0]
    body = part.split("<tbody>", 1)[1].split("</tbody>", 1)[0]
    return [re.findall(r"<td[^>]*>(.*?)</td>", row) for row in body.split("</tr>") if "<td" in row]


def test_residuals_before_are_measured_minus_nominal_and_nil_after(noiseless):
    machine, _, meas, page = noiseless
    rows = _table_after(page, "Residual per measurement")
    with open(meas, newline="") as f:
        measured = list(csv.DictReader(line for line in f if not line.startswith("#")))
    assert len(rows) == len(measured) == 16
    for row, m in zip(rows, measured):
        nominal = json.loads(cli("eval", machine, "--set", f"Ap={m['Ap']}", "--set", f"Cp={m['Cp']}",
                                 "--format", "json").stdout)["position"]
        size = 1000 * math.dist([float(m[c]) for c in "xyz"], nominal)          # µm
        assert float(row[1]) == pytest.approx(size, rel=1e-3)
        assert float(row[2]) < 1e-3
    dispersion = _table_after(page, "Dispersion per axis")
    assert [d[0] for d in dispersion] == ["x", "y", "z"]
    assert all(float(d[1]) > 1.0 and float(d[2]) < 1e-3 for d in dispersion)


def test_values_are_the_params_files_and_the_unseen_are_named(noiseless):
    _, params, _, page = noiseless
    with open(params) as f:
        truth = yaml.safe_load(f)["values"]
    shown = {r[0]: (float(r[1]), r[3]) for r in _table_after(page, "Identified values")}
    assert set(shown) == {"ThetaAs", "Oas", "Ocx", "Ocy", "ThetaCh", "ThetaCv"}
    for name, (value, unit) in shown.items():
        expected = truth.get(name, 0.0) * (1000.0 if unit == "µm" else 1.0)     # the file: mm and arcsec
        assert value == pytest.approx(expected, abs=1e-3), name
    unseen = [r[0] for r in _table_after(page, "What these measurements could not see")]
    assert sorted(unseen) == ["DY", "ThetaAv"]
    assert np.isfinite([float(x) for x in re.findall(r"class=n>(-?[0-9.e+-]+)<", page)]).all()


NUTATING_TRUTH = {"EU0B": 12, "EV0B": -8, "EAU0B": 15, "EAV0B": -10, "EX0C": 6, "EY0C": -9, "EA0C": 12, "EB0C": 20}


def test_probe_fit_report_has_the_true_values_backlash_and_what_a_sphere_cannot_see(tmp_path):
    """probe fit --report on the nutating table, probed (simulated, 1 µm) with known errors (µm,
    arcsec), a backlash of B of 0.005 deg (18 arcsec) and the sphere 0.1, 0.2 mm off: the values are
    those errors within 4 sigma, the backlash 18 arcsec within 4 sigma, and the two zero angles a
    sphere cannot see (C's turns the part, B's is C's tilt about y: test_probe reasons both) are
    named, not given a value."""
    machine = machine_path("nutating_bc45")
    sphere = ["--sphere", "50,30,80", "--radius", "12.5", "--stylus", "2"]
    truth, plan, log, report = tmp_path / "t.yaml", tmp_path / "plan.csv", tmp_path / "probe.log", tmp_path / "r.html"
    truth.write_text(yaml.safe_dump({"machine": "nutating_bc45", "values": NUTATING_TRUTH}))
    cli("probe", "plan", machine, *sphere, "--backlash-step", "5", "--csv", plan)
    cli("probe", "simulate", machine, plan, "--sphere", "50.1,30.2,80", "--radius", "12.5", "--stylus", "2",
        "--params", truth, "--backlash", "B=0.005", "-o", log)
    proc = cli("probe", "fit", machine, log, "--plan", plan, *sphere, "--report", report)
    assert f"wrote {report}" in proc.stdout
    page = report.read_text(encoding="utf-8")
    shown = {r[0]: (float(r[1]), float(r[2])) for r in _table_after(page, "Identified values")}
    assert set(shown) == set(NUTATING_TRUTH)
    for name, (value, u) in shown.items():
        assert abs(value - NUTATING_TRUTH[name]) <= 4 * u, name
    backlash = re.search(r"rotary backlash of B</th><td>(\S+) ± (\S+) arcsec", page)
    assert abs(float(backlash.group(1)) - 18.0) <= 4 * float(backlash.group(2))
    assert sorted(r[0] for r in _table_after(page, "What these measurements could not see")) == ["EB0B", "EC0C"]
    dispersion = {r[0]: (float(r[1]), float(r[2])) for r in _table_after(page, "Dispersion per axis")}
    assert set(dispersion) == {"B", "C", "all"} and all(a < b / 5 for b, a in dispersion.values())
    assert page.count("<svg") == 4


def test_a_report_over_an_input_or_not_named_html_is_refused_and_nothing_written(tmp_path):
    meas = tmp_path / "m.csv"
    machine = machine_path("angle_head")
    cli("simulate-measurements", machine, "--params", f"{PARAMS}/angle_head-fig3.yaml", "--seed", "1", "-o", meas)
    before = meas.read_bytes()
    for report, message in ((meas, "--report"), (tmp_path / "r.txt", "must end in .html")):
        proc = cli("identify", machine, meas, "--assume-zero", "DY,ThetaAv", "--report", report, check=False)
        assert proc.returncode == 2 and message in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert meas.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["m.csv"]
