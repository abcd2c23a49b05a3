"""chaincomp budget --component wx|wy|wz: a tool frame's rotation vector ω. Truth by hand
from the two-axis head of test_tool_frame, Rz(A)·Rx(e1)·Ry(B + e2)·Rz(e3): to first order
ω = e1·Rz(A)x + e2·Rz(A)y + e3·Rz(A)Ry(B)z, so wz = e3·cos B, and its worst case over the
grid is e3's bound, at B = 0."""

from __future__ import annotations

import json
import math

import pytest

from helpers import head_file, run_verb

ARCSEC = math.pi / (180 * 3600)
TOLERANCES = """machine: head
tolerances:
  e1: {bound: 10 arcsec, distribution: uniform}
  e2: {bound: 10 arcsec, distribution: uniform}
  e3: {bound: 7 arcsec, distribution: uniform}
  d1: {bound: 5 um, distribution: uniform}
"""


@pytest.mark.slow
def test_budget_of_the_rotation_vector_and_its_plot(tmp_path):
    tol = tmp_path / "tol.yaml"
    tol.write_text(TOLERANCES)
    png = tmp_path / "wz.png"
    code, out, err = run_verb("budget", head_file(tmp_path), "--tolerances", tol, "--component", "wz",
                         "--plot", png, "--format", "json")
    assert code == 0, err
    wz = json.loads(out)["components"]["wz"]
    assert math.isclose(wz["worst"]["max"], 7 * ARCSEC, rel_tol=1e-9), wz
    assert wz["worst"]["at"]["B"] == 0
    assert png.stat().st_size > 10_000


@pytest.mark.slow
def test_component_w_needs_a_tool_frame(tmp_path):
    tol = tmp_path / "tol.yaml"
    tol.write_text(TOLERANCES)
    head = head_file(tmp_path)
    head.write_text(head.read_text().replace(", reference: [0, 1, 0]", ""))
    code, _, err = run_verb("budget", head, "--tolerances", tol, "--component", "wx", "--plot", tmp_path / "x.png")
    assert code == 2
    assert "--component wx: this machine has no tool frame (tool.reference or tool.rotation)" in err, err
    assert not (tmp_path / "x.png").exists()
