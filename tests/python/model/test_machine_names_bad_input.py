"""The errors a machine file names or chaincomp names for it (dh, mdh, beta elements, loop branches):
no collision with a declared name, no error shared by two elements."""

import pytest

from helpers import arm_file, derive_text, one_error_line, refused_field, run_in_process


def test_auto_error_colliding_with_a_declared_error_is_refused(tmp_path):
    # joint 1's auto dd1 and joint 2's named dd1 used to be one symbol, silently: two physical
    # errors that calibration could never tell apart
    p = arm_file(tmp_path, "collide", "  - {name: dd1, role: error, unit: um}\n",
            "  - {dh: {theta: q1, d: 5, a: 10, alpha: pi/2}, errors: auto}\n"
            "  - {dh: {theta: q2, d: 0, a: 10, alpha: 0}, errors: {d: dd1}}\n")
    line = one_error_line(run_in_process("lint", str(p)), "lint", "collide.yaml:7:", "chain[0].errors.d", "dd1", "line 5")
    assert "auto" in line


def test_named_error_equal_to_an_earlier_auto_name_is_refused(tmp_path):
    p = arm_file(tmp_path, "collide2", "",
            "  - {dh: {theta: q1, d: 5, a: 10, alpha: pi/2}, errors: auto}\n"
            "  - {dh: {theta: q2, d: 0, a: 10, alpha: 0}, errors: {d: dd1}}\n")
    one_error_line(run_in_process("lint", str(p)), "lint", "collide2.yaml:7:", "chain[1].errors.d", "dd1", "line 6")


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


@pytest.mark.slow
def test_auto_errors_of_two_loop_branches_do_not_merge(tmp_path):
    # Joint 1 of each branch auto-named dtheta1, dd1, ...: two physical errors silently became
    # one symbol (and the loop's two dtheta1 rotations cancelled).
    refused_field(derive_text(tmp_path, LOOP.replace("WORK", "auto")), "loop.workpiece[0].errors.theta", "already")


@pytest.mark.slow
def test_explicit_names_in_the_second_branch_load(tmp_path):
    proc = derive_text(tmp_path, LOOP.replace("WORK", "{theta: wt1, d: wd1}"))
    assert proc.returncode == 0, proc.stderr
    assert "wt1" in proc.stdout and "dtheta1" in proc.stdout


@pytest.mark.slow
def test_two_betas_after_one_joint_do_not_share_an_error(tmp_path):
    proc = derive_text(tmp_path, "name: beta_test\nsymbols:\n"
                  "  - {name: q1, role: axis, unit: deg, limits: [-360, 360]}\n"
                  "chain:\n  - {dh: {theta: q1, d: 10, a: 5, alpha: 0}, errors: auto}\n"
                  "  - {beta: 0, errors: auto}\n  - {beta: 0, errors: auto}\n"
                  "tool:\n  point: [0, 0, 0]\n  direction: [0, 0, 1]\n")
    refused_field(proc, "chain[2].errors.beta", "already")
