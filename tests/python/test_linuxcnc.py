"""chaincomp under LinuxCNC (issue #18): the headless simulated five_axis_ac
(configs/linuxcnc/five_axis_ac, trivkins) runs its G-code program with compensation off and
through the realtime component chaincomp_rt; every servo period is recorded (halsampler) and
the true machine, the exact model with the params in the test, gives the actual tool point at
the positions the drives got. One LinuxCNC at a time (cnc.py holds a lock), as an unprivileged
user; skipped with the reason when LinuxCNC is not installed (tools/setup-linuxcnc installs it)."""

import os
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT

sys.path.insert(0, os.path.join(ROOT, "configs", "linuxcnc"))
import cnc  # noqa: E402

from chaincomp import ExactModel, load_machine, load_params  # noqa: E402

MACHINE = os.path.join(ROOT, "configs", "machines", "five_axis_ac.yaml")
PARAMS = os.path.join(ROOT, "configs", "params", "five_axis_ac-demo.yaml")
PROGRAM_DWELLS = 5  # G4s in configs/linuxcnc/five_axis_ac/program.ngc

pytestmark = pytest.mark.skipif(cnc.unavailable() is not None, reason=str(cnc.unavailable()))


@pytest.fixture(scope="module")
def machine():
    return load_machine(MACHINE)


@pytest.fixture(scope="module")
def params(machine):
    return load_params(PARAMS, machine)


@pytest.fixture(scope="module")
def rt_module():
    if os.geteuid() != 0:
        pytest.skip("installing chaincomp_rt into LinuxCNC's module folder needs root")
    proc = subprocess.run([os.path.join(ROOT, ".venv", "bin", "chaincomp"), "build", "--linuxcnc", MACHINE,
                           "--params", PARAMS, "--install"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr


def program_dwells(run):
    """The program's dwells: the still stretches after the first one (homing, settling)."""
    found = cnc.dwells(run.commands)
    assert len(found) == PROGRAM_DWELLS + 1, [(s.start, s.stop) for s in found]
    return found[0], found[1:]


def completed(run):
    assert run.returncode == 0, run.log[-3000:]
    assert [e["event"] for e in run.events if e["event"] != "error"] == ["homed", "run", "done"], run.events
    assert not [e for e in run.events if e["event"] == "error"], run.events
    assert len(run.samples) > 3000
    tags = run.samples[:, 0]
    assert np.all(np.diff(tags) == 1), "halsampler lost periods"


@pytest.fixture(scope="module")
def off_run():
    return cnc.run("off")


@pytest.fixture(scope="module")
def rt_run(rt_module):
    return cnc.run("rt")


def test_without_compensation_the_error_is_the_exact_models(off_run, machine, params):
    completed(off_run)
    assert np.all(off_run.corrections == 0.0)
    _, dwells = program_dwells(off_run)
    exact = ExactModel(machine)
    sizes = []
    for s in dwells:
        q = off_run.commands[s.start]
        axes = {a.name: q[i] * (np.pi / 180 if a.unit.kind == "angle" else 1.0) for i, a in enumerate(machine.axes)}
        expected, _ = exact.error({**params, **axes})
        point, _ = cnc.tool_errors(machine, params, off_run.commands[s], off_run.drives[s])
        np.testing.assert_allclose(point, np.tile(np.array(expected, float), (len(point), 1)), atol=1e-12)
        sizes.append(np.linalg.norm(expected) * 1e3)
    assert min(sizes) > 10.0, sizes  # tens of µm: the demo params' errors


def test_realtime_component_puts_the_tool_on_the_programmed_point(rt_run, machine, params):
    completed(rt_run)
    first, dwells = program_dwells(rt_run)
    point, direction = cnc.tool_errors(machine, params, rt_run.commands, rt_run.drives)
    err_nm = np.linalg.norm(point, axis=1) * 1e6
    for s in dwells:
        assert err_nm[s].max() < 1.0, (s, err_nm[s].max())
        assert np.abs(rt_run.corrections[s]).max() > 1e-3  # a real correction is applied there
    # every servo period from the first program dwell on, in motion too (the move from home
    # leaves A = 0, a singular pose where the rate limit spreads out a large C correction)
    program = slice(dwells[0].start, len(err_nm))
    assert err_nm[program].max() < 1.0, err_nm[program].max()
    assert np.linalg.norm(direction[program], axis=1).max() < 1e-8
    assert rt_run.samples[:, cnc.COL_FAULT].max() == 0
