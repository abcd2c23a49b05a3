"""Sphere probing end to end through LinuxCNC (issue #45 item 6, tools/linuxcnc-demo --probing):
chaincomp probe plan -> LinuxCNC runs the program on the simulated five_axis_ac, whose probe
input the realtime component sphere_probe drives from the true machine (the exact model with
five_axis_ac-demo.yaml) touching a virtual sphere -> probe fit -> chaincomp_rt with the fitted
params -> the program again. About 4 minutes; skipped without LinuxCNC or root (the modules go
into LinuxCNC's module folder)."""

import os
import shutil
import sys

import numpy as np
import pytest

from helpers import ROOT

sys.path.insert(0, os.path.join(ROOT, "configs", "linuxcnc"))
import cnc  # noqa: E402
import probing  # noqa: E402

from chaincomp import ExactModel, load_machine, load_params  # noqa: E402

pytestmark = [pytest.mark.slow, pytest.mark.skipif(cnc.unavailable() is not None, reason=str(cnc.unavailable())),
              pytest.mark.skipif(os.geteuid() != 0, reason="installing HAL modules into LinuxCNC's folder needs root")]

TOUCHES = 9 * 6   # probing.POSITIONS, six touches each
STEP_MM = probing.FEED / 60.0 * 1e-3   # the probing move in one 1 ms servo period


@pytest.fixture(scope="module")
def route():
    r = probing.route()
    yield r
    if not os.environ.get("CHAINCOMP_KEEP_RUNS"):
        shutil.rmtree(r["folder"], ignore_errors=True)


def test_second_probing_shows_the_dispersion_down_to_a_fifth_or_less(route):
    """Issue #45's acceptance: the compensated machine's sphere centres scatter at most 20 % as
    far as the first probing's; the first is the machine's errors (tens of um and more)."""
    assert route["first_um"] > 50.0, route
    assert route["second_um"] <= 0.2 * route["first_um"], route
    for axis, (first, second) in route["per_axis_um"].items():
        assert second <= 0.2 * first, (axis, route)


def test_each_touch_is_where_the_true_machine_meets_the_sphere(route):
    """The first probing (no compensation: the drives are the logged positions): LinuxCNC's log
    line per G38.2 (X Y Z A B C U V W) put through the true machine, computed here in Python,
    lies on the contact sphere (sphere + stylus radius around the true centre), up to one servo
    period's move inside it: the probe trips in the period the tool reaches it, and LinuxCNC
    logs that period's position (one period late would be a whole step inside)."""
    machine = load_machine(probing.MACHINE)
    params = load_params(probing.TRUE_PARAMS, machine)
    rows = np.loadtxt(route["logs"][0], ndmin=2)
    assert rows.shape == (TOUCHES, 9)
    joints = rows[:, [0, 1, 2, 3, 5]]   # X Y Z A C: five_axis_ac's X Y Z Ap Cp under trivkins
    point, _ = ExactModel(machine).pose({**params, **cnc.to_internal(machine, joints)})
    gap = np.linalg.norm(np.stack(point, axis=1) - probing.TRUE_SPHERE, axis=1) - (probing.RADIUS + probing.STYLUS)
    # the log's %f: 1 nm and 1e-6 deg (3 nm at the tool's 150 mm)
    assert np.all(gap <= 5e-6), gap.max()
    assert np.all(gap >= -STEP_MM - 5e-6), gap.min()
    assert len(np.loadtxt(route["logs"][1], ndmin=2)) == TOUCHES
