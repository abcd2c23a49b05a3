"""lint warns where derive and report will be slow: a rotation by a constant whose sine and
cosine are exact irrationals (pi/4: sqrt(2)/2, pi/6: sqrt(3)/2, pi/12), which the derivation
carries as atoms its fast printer does not take (#41). A rotation whose sine and cosine are
rational (0, pi/2, pi), a decimal (a number), an axis or a named constant draws no warning,
and no bundled machine draws one."""

from __future__ import annotations

import pytest

from chaincomp import lint, load_machine

from helpers import BUNDLED, machine_path

MACHINE = """name: turns
description: rotations by constants
rotation_sense: right_hand
symbols:
  - {name: X, role: axis, unit: mm, limits: [0, 100], meaning: slide}
  - {name: C, role: axis, unit: deg, limits: [-180, 180], meaning: table}
  - {name: Yp, role: constant, unit: deg, nominal: 50, meaning: a fixed angle kept symbolic}
chain:
  - {translate: [X, 0, 0]}
  - {rotate: x, angle: ANGLE}
  - {rotate: y, angle: Yp}
  - {rotate: z, angle: C}
tool: {point: [10, 20, 30], direction: [0, 0, 1]}
"""


def findings(tmp_path, angle):
    path = tmp_path / "turns.yaml"
    path.write_text(MACHINE.replace("ANGLE", angle))
    return [f for f in lint(load_machine(str(path))) if "exact sine" in f.message]


# sin(pi/12) = (sqrt(6) - sqrt(2))/4; sin(pi/3) = sqrt(3)/2; sin(pi/4) = sqrt(2)/2
@pytest.mark.parametrize("angle", ["pi/4", "-3*pi/4", "pi/3", "pi/12", "pi/6 + 0"])
def test_an_irrational_exact_sine_or_cosine_is_named_at_its_line(angle, tmp_path):
    got = findings(tmp_path, angle)
    assert len(got) == 1, got
    assert got[0].line == 10 and got[0].field == "chain"
    assert "sqrt" in got[0].message and "write the angle as a decimal" in got[0].message


@pytest.mark.parametrize("angle", ["0", "pi/2", "-pi", "3*pi/2", "0.785398163397448", "1.57079632679", "C + pi/4"])
def test_rational_sines_numbers_and_moving_angles_draw_none(angle, tmp_path):
    assert findings(tmp_path, angle) == []


@pytest.mark.parametrize("name", BUNDLED)
def test_no_bundled_machine_draws_it(name):
    assert [f for f in lint(load_machine(machine_path(name))) if "exact sine" in f.message] == []
