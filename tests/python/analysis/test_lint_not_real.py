"""chaincomp lint on an expression that is not real somewhere within the axis limits (issue #38
item 5): sqrt(X) with X in [-100, 100], acos or asin beyond 1, a fractional power of a negative.
The loader checks expressions at one pose; lint samples poses across the limits, where the
model is then NaN. A NaN gain was read as zero: "axis X never moves the tool point". Now lint
names the expression, its line and a pose where it fails, and says nothing of gains it cannot
read.

The truth: Python's math module raises ValueError for sqrt of a negative and acos, asin beyond
1 (IEEE 754 invalid operation) at the pose lint names, and returns a number at the poses of an
expression real over the limits.
"""

from __future__ import annotations

import math
import re

import pytest

from helpers import cli, write_file

MACHINE = """\
name: notreal
length_unit: mm
rotation_sense: right_hand
symbols:
  - {name: X, role: axis, unit: mm, limits: [-100, 100]}
  - {name: Y, role: axis, unit: mm, limits: [-100, 100]}
  - {name: C, role: axis, unit: deg, limits: [-90, 90]}
  - {name: EXX, role: error, unit: um}
  - {name: EYY, role: error, unit: um}
  - {name: ECC, role: error, unit: arcsec}
chain:
  - {rotate: z, angle: ANGLE}
  - {translate: [X + EXX, Y + EYY, 50]}
tool: {point: [0, 0, 0], direction: [0, 0, 1]}
"""

# (angle as written, its function of X in mm (rad out), symbols it names)
NOT_REAL = [
    ("C + ECC + 1e-3*sqrt(X)", lambda x: 1e-3 * math.sqrt(x)),
    ("C + ECC + acos(X/50)", lambda x: math.acos(x / 50)),
    ("C + ECC + asin(X/75) + 0*Y", lambda x: math.asin(x / 75)),
    ("C + ECC + 1e-3*(X + 20)^(1/2)", lambda x: 1e-3 * math.sqrt(x + 20)),
    ("C + ECC + 1e-3*(X + 50)^(3/2)", lambda x: 1e-3 * math.sqrt(x + 50) ** 3),
]


def lint(tmp_path, angle):
    text = MACHINE.replace("ANGLE", angle)
    path = write_file(tmp_path, "m.yaml", text)
    proc = cli("lint", path, check=False)
    return proc, path, text


@pytest.mark.parametrize("angle,f", NOT_REAL, ids=[a for a, _ in NOT_REAL])
def test_an_expression_not_real_over_the_limits_is_named_with_a_pose(tmp_path, angle, f):
    proc, path, text = lint(tmp_path, angle)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0 and "Traceback" not in out, out
    line = next(i for i, t in enumerate(text.splitlines(), 1) if "rotate: z" in t)
    m = re.search(rf"{re.escape(path)}:{line}: chain: '{re.escape(angle)}' is not real \(or not finite\) at "
                  r"(X = (-?[0-9.e+-]+) mm[^(]*), within the axis limits \(at \d+ of the \d+ poses lint tries", out)
    assert m, out
    x = float(m.group(2))
    assert -100 <= x <= 100
    with pytest.raises(ValueError):   # IEEE invalid: the function is not real there
        f(x)
    # a NaN gain is no zero gain: no symbol is said never to move the tool
    assert "never moves" not in out, out
    assert cli("lint", path, "--strict", check=False).returncode == 2


def test_an_expression_real_over_the_limits_is_not_reported(tmp_path):
    proc, _, _ = lint(tmp_path, "C + ECC + 1e-3*sqrt(X + 100.5)")
    assert proc.returncode == 0 and "not real" not in proc.stdout + proc.stderr, proc.stderr
    for x in (-100.0, 0.0, 100.0):
        assert math.isfinite(1e-3 * math.sqrt(x + 100.5))


def test_not_real_in_a_translation_and_the_tool_point(tmp_path):
    text = MACHINE.replace("ANGLE", "C + ECC").replace("[X + EXX, Y + EYY, 50]", "[X + EXX, Y + EYY, sqrt(Y)]")
    text = text.replace("point: [0, 0, 0]", "point: [0, 0, asin(X/80)]")
    path = write_file(tmp_path, "m.yaml", text)
    out = cli("lint", path, check=False).stderr
    assert re.search(rf"{re.escape(path)}:\d+: chain: 'sqrt\(Y\)' is not real \(or not finite\) at Y = -", out), out
    tool = next(i for i, t in enumerate(text.splitlines(), 1) if t.startswith("tool:"))
    # |X/80| > 1 only beyond 80 mm: at the limits, which lint tries besides its samples
    assert re.search(rf"{re.escape(path)}:{tool}: tool\.point: 'asin\(X/80\)' is not real \(or not finite\) at "
                     r"X = -?100 mm", out), out
    assert "never moves" not in out, out


def test_an_error_that_truly_never_moves_the_tool_is_still_reported(tmp_path):
    """The not-real expression does not hide a finding lint can read: an error EZZ that only
    turns the tool about its own axis through the tool point moves neither point nor
    direction (by hand: a rotation about z fixes (0, 0, 0) and (0, 0, 1))."""
    text = MACHINE.replace("ANGLE", "C + ECC").replace("[X + EXX, Y + EYY, 50]", "[X + EXX, Y + EYY, sqrt(X)]")
    text = text.replace("  - {name: ECC, role: error, unit: arcsec}\n",
                        "  - {name: ECC, role: error, unit: arcsec}\n  - {name: EZZ, role: error, unit: arcsec}\n")
    text = text.replace("tool: {", "  - {rotate: z, angle: EZZ}\ntool: {")
    path = write_file(tmp_path, "m.yaml", text)
    out = cli("lint", path, check=False).stderr
    assert "'sqrt(X)' is not real" in out, out
    assert "error EZZ never moves the tool point or direction" in out, out
    assert "axis X never moves" not in out and "error EXX never moves" not in out, out
