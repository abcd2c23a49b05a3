"""Bugs found in the second review of the session's changes, each pinned by a test that
failed before its fix."""

import os
import subprocess
import sys

import pytest

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))


def derive(tmp_path, text):
    path = tmp_path / "m.yaml"
    path.write_text(text)
    return subprocess.run([sys.executable, "-m", "chaincomp.cli.main", "derive", str(path)], capture_output=True,
                          text=True, cwd=ROOT, timeout=120)


def refused(proc, field, word):
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert f" {field}: " in proc.stderr and word in proc.stderr, proc.stderr


def test_abs_of_an_error_is_not_analytic(tmp_path):
    # sqrt(e^2) is |e|: it has no derivative at zero error, so no Taylor series to truncate.
    proc = derive(tmp_path, "name: abs_test\nsymbols:\n"
                  "  - {name: x, role: axis, unit: mm, limits: [-100, 100]}\n"
                  "  - {name: e, role: error, unit: um}\n"
                  "chain:\n  - {translate: [x, 0, 0]}\n  - {translate: ['sqrt(e^2)', 0, 0]}\n"
                  "tool:\n  point: [0, 0, 0]\n")
    refused(proc, "chain[1].translate[0]", "absolute value")


def test_abs_away_from_zero_is_fine(tmp_path):
    proc = derive(tmp_path, "name: abs_ok\nsymbols:\n"
                  "  - {name: x, role: axis, unit: mm, limits: [-100, 100]}\n"
                  "  - {name: e, role: error, unit: um}\n"
                  "chain:\n  - {translate: [x, 0, 0]}\n  - {translate: ['sqrt((e + 1)^2)', 0, 0]}\n"
                  "tool:\n  point: [0, 0, 0]\n")
    assert proc.returncode == 0, proc.stderr


LOOP = """name: loop_test
symbols:
  - {name: q1, role: axis, unit: deg, limits: [-360, 360]}
  - {name: q2, role: axis, unit: deg, limits: [-360, 360]}
loop:
  tool:
    - {dh: {theta: q1, d: 10, a: 5, alpha: 0}, errors: auto}
  workpiece:
    - {dh: {theta: q2, d: 20, a: 7, alpha: 0}, errors: WORK}
tool:
  point: [0, 0, 0]
  direction: [0, 0, 1]
"""


def test_auto_errors_of_two_loop_branches_do_not_merge(tmp_path):
    # Joint 1 of each branch auto-named dtheta1, dd1, ...: two physical errors silently became
    # one symbol (and the loop's two dtheta1 rotations cancelled).
    refused(derive(tmp_path, LOOP.replace("WORK", "auto")), "loop.workpiece[0].errors.theta", "already")


def test_explicit_names_in_the_second_branch_load(tmp_path):
    proc = derive(tmp_path, LOOP.replace("WORK", "{theta: wt1, d: wd1}"))
    assert proc.returncode == 0, proc.stderr
    assert "wt1" in proc.stdout and "dtheta1" in proc.stdout


def test_two_betas_after_one_joint_do_not_share_an_error(tmp_path):
    proc = derive(tmp_path, "name: beta_test\nsymbols:\n"
                  "  - {name: q1, role: axis, unit: deg, limits: [-360, 360]}\n"
                  "chain:\n  - {dh: {theta: q1, d: 10, a: 5, alpha: 0}, errors: auto}\n"
                  "  - {beta: 0, errors: auto}\n  - {beta: 0, errors: auto}\n"
                  "tool:\n  point: [0, 0, 0]\n  direction: [0, 0, 1]\n")
    refused(proc, "chain[2].errors.beta", "already")
