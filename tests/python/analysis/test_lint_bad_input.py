"""chaincomp lint on machine files a user writes: a long-travel slide that moves the tool, limits in
the other angle unit, and the parallel-axes advice checked by the rank of an independent numpy model."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from arm_models import UR5_A, UR5_ALPHA, UR5_D, mod_link, ry, std_link
from helpers import M4, cli, edited, write_file


def test_lint_sees_a_slide_of_very_long_travel_move_the_tool(tmp_path):
    """A slide with limits of +-1e14 mm (a URDF's prismatic limits of +-1e11 m): at such values a
    step of 1e-6 mm does not change the double, and lint said 'axis X never moves the tool point'.
    The slide moves the tool by dx/dX = 1 (by hand). An error that truly never moves it (an ez
    turn about the tool's own axis through the tool point) is still reported."""
    text = edited(M4, "limits: [-300, 300]}", "limits: [-1e14, 1e14]}")
    text = edited(text, "{translate: [0, 0, -L]}", "{translate: [0, 0, -L]}\n  - {errors: {ez: EZT}}")
    text = edited(text, "  - {name: EXB, role: error, unit: um}",
                   "  - {name: EXB, role: error, unit: um}\n  - {name: EZT, role: error, unit: arcsec}")
    path = write_file(tmp_path, "m.yaml", text)
    proc = cli("lint", path)
    assert "axis X never moves" not in proc.stderr + proc.stdout
    assert "error EZT never moves the tool point or direction" in proc.stderr + proc.stdout


# ----------------------------------------------------------------------------- limits in the other angle unit

@pytest.mark.parametrize("unit, limits, message", [
    ("deg", "[-3.14159, 3.14159]", "axis B's limits [-3.14159, 3.14159] deg look like radians (-pi, pi): a travel "
                                   "of only 6.28 deg; if they are radians, write [-180, 180] or declare the axis "
                                   "in rad"),
    ("deg", "[0, 6.2832]", "deg look like radians (0, 2 pi): a travel of only 6.28 deg; if they are radians, write "
                           "[0, 360]"),
    ("deg", "[-1.5708, 1.5708]", "look like radians (-pi/2, pi/2)"),
    ("rad", "[-180, 180]", "axis B's limits [-180, 180] rad are 57.3 turns: if they are degrees, declare the axis "
                           "in deg"),
    ("deg", "[-3, 3]", None), ("deg", "[-90, 90]", None), ("rad", "[-3.1416, 3.1416]", None),
])
def test_lint_warns_of_limits_written_in_the_other_angle_unit(tmp_path, unit, limits, message):
    """B in deg with limits [-3.14159, 3.14159]: every random set-up, every protocol angle and
    every plot then stays within +-3 deg, without a word. 180/pi = 57.2958 (by hand)."""
    text = edited(M4, "{name: B, role: axis, unit: deg, limits: [-90, 90]}",
                   f"{{name: B, role: axis, unit: {unit}, limits: {limits}}}")
    proc = cli("lint", write_file(tmp_path, "m.yaml", text))
    assert proc.returncode == 0
    if message is None:
        assert "limits" not in proc.stderr
    else:
        assert f"chaincomp lint: warning: {tmp_path / 'm.yaml'}:10: symbols.B.limits: " in proc.stderr
        assert message in proc.stderr
        assert cli("lint", write_file(tmp_path, "m.yaml", text), "--strict", check=False).returncode == 2

# A UR5 in both conventions (joints 2, 3, 4 parallel), and the same arm written in Craig's
# (each link's a and alpha moved to the next link).
ARM = {"dh": {"d": UR5_D, "a": UR5_A, "alpha": UR5_ALPHA},
       "mdh": {"d": UR5_D, "a": [0.0] + UR5_A[:-1], "alpha": [0.0] + UR5_ALPHA[:-1]}}


def arm_text(kind, no_d=(), betas=()):
    p = ARM[kind]
    s = "name: arm\nsymbols:\n" + "".join(f"  - {{name: q{j}, role: axis, unit: deg, limits: [-360, 360]}}\n"
                                        for j in range(1, 7)) + "chain:\n"
    for i in range(6):
        j = i + 1
        err = "{theta: auto, a: auto, alpha: auto}" if j in no_d else "auto"
        body = (f"theta: q{j}, d: {p['d'][i]}, a: {p['a'][i]}, alpha: {p['alpha'][i]!r}" if kind == "dh" else
                f"alpha: {p['alpha'][i]!r}, a: {p['a'][i]}, theta: q{j}, d: {p['d'][i]}")
        s += f"  - {{{kind}: {{{body}}}, errors: {err}}}\n" + ("  - {beta: 0, errors: auto}\n" if j in betas else "")
    return s + "  - {translate: [10, 0, 50]}\ntool:\n  point: [0, 0, 0]\n  direction: [0, 0, 1]\n"


def numpy_rank(kind, no_d, betas):
    """Rank of d(point, direction)/d(errors) over random poses, by central differences of the
    textbook link product (theta, d, a, alpha errors per joint, less the dropped d; betas)."""
    p = ARM[kind]
    cols = [(j, k) for j in range(1, 7) for k in ("theta", "d", "a", "alpha") if not (k == "d" and j in no_d)]
    cols += [(j, "beta") for j in betas]

    def pose(q, e):
        T = np.eye(4)
        for i in range(6):
            j = i + 1
            th, d, a, al = (q[i] + e.get((j, "theta"), 0), p["d"][i] + e.get((j, "d"), 0),
                            p["a"][i] + e.get((j, "a"), 0), p["alpha"][i] + e.get((j, "alpha"), 0))
            T = T @ (std_link(th, d, a, al) if kind == "dh" else mod_link(al, a, th, d))
            if j in betas:
                T = T @ ry(e.get((j, "beta"), 0))
        T = T @ np.array([[1, 0, 0, 10], [0, 1, 0, 0], [0, 0, 1, 50], [0, 0, 0, 1.0]])
        return np.concatenate([T[:3, 3], T[:3, 2]])

    rng = np.random.default_rng(7)
    rows = []
    for _ in range(30):
        q = rng.uniform(-math.pi, math.pi, 6)
        rows.append(np.array([(pose(q, {c: 1e-6}) - pose(q, {c: -1e-6})) / 2e-6 for c in cols]).T)
    s = np.linalg.svd(np.vstack(rows), compute_uv=False)
    return int((s > 1e-7 * s[0]).sum())


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["dh", "mdh"])
def test_following_the_parallel_axes_advice_adds_a_freedom_per_beta(tmp_path, kind):
    from chaincomp import load_machine
    from chaincomp.analysis.lint import lint
    path = tmp_path / "arm.yaml"
    path.write_text(arm_text(kind))
    advice = [f.message for f in lint(load_machine(str(path))) if "parallel" in f.message]
    assert len(advice) == 2, advice
    no_d = [int(re.search(r"d error dd(\d+)", a).group(1)) for a in advice]
    betas = [int(re.search(r"after joint (\d+)", a).group(1)) for a in advice]
    # each beta must describe the missing tilt (a beta where none is missing is redundant)
    assert numpy_rank(kind, no_d, betas) == numpy_rank(kind, (), ()) + 2, (no_d, betas)


def test_no_parallel_warning_against_the_base_frame(tmp_path):
    # mdh joint 1's alpha is the twist from the base frame, not from a joint: d1 is defined.
    from chaincomp import load_machine
    from chaincomp.analysis.lint import lint
    path = tmp_path / "arm.yaml"
    path.write_text(arm_text("mdh"))
    assert not [f for f in lint(load_machine(str(path))) if f.field == "symbols.dd1"]


def test_parallel_axes_lint_keeps_loop_branches_apart(tmp_path):
    # joints are numbered per branch: the workpiece's joint 2 is not the tool's
    from chaincomp import load_machine
    from chaincomp.analysis.lint import lint
    path = tmp_path / "loop.yaml"
    path.write_text("name: loop_dh\nsymbols:\n" + "".join(
        f"  - {{name: q{j}, role: axis, unit: deg, limits: [-360, 360]}}\n" for j in range(1, 5)) +
        "  - {name: td2, role: error, unit: um}\n  - {name: wd2, role: error, unit: um}\n"
        "loop:\n  tool:\n"
        "    - {dh: {theta: q1, d: 10, a: 300, alpha: 0}}\n"
        "    - {dh: {theta: q2, d: 20, a: 200, alpha: 0}, errors: {d: td2}}\n"
        "  workpiece:\n"
        "    - {dh: {theta: q3, d: 30, a: 100, alpha: 1.5707963267948966}}\n"
        "    - {dh: {theta: q4, d: 40, a: 50, alpha: 1.5707963267948966}, errors: {d: wd2}}\n"
        "tool:\n  point: [0, 0, 0]\n  direction: [0, 0, 1]\n")
    warned = {f.field for f in lint(load_machine(str(path))) if "parallel" in f.message}
    assert warned == {"symbols.td2"}
