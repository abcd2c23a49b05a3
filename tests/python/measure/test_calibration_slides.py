"""simulate-calibration's slides on a machine whose tables move (vmc_xyz: table X on saddle Y,
written as the conventions say, each table's error block negated before its translation):
every error goes to the axis and kind its ISO 230-1 name says (E<motion><axis>: positioning
along the axis, straightness across it, roll about it, pitch/yaw about the others), and the
tables it writes move the tool relative to the workpiece as the standard reads them."""

import numpy as np

from chaincomp import ExactModel, load_machine, load_params
from chaincomp.measure.calibration import find_slides
from chaincomp.cli.main import main

from helpers import machine_path

KIND = {("X", "X"): "positioning", ("Y", "Y"): "positioning", ("Z", "Z"): "positioning",
        ("A", "X"): "roll", ("B", "Y"): "roll", ("C", "Z"): "roll"}


def iso_kind(name: str) -> tuple[str, str]:
    motion, axis = name[1], name[2]
    if motion in "XYZ":
        return axis, KIND.get((motion, axis), "straightness")
    return axis, KIND.get((motion, axis), "tilt")


def test_table_axes_get_their_own_errors():
    m = load_machine(machine_path("vmc_xyz"))
    found = {c.error: (s.axis, c.kind) for s in find_slides(m) for c in s.components}
    motions = [e.name for e in m.errors if len(e.name) == 3]   # the 18 error motions (not EC0Y ...)
    assert len(motions) == 18 and set(found) == set(motions)
    for name in motions:
        assert found[name] == iso_kind(name), name


def test_simulated_positioning_table_moves_the_tool_as_iso_reads_it(tmp_path, capsys):
    path = machine_path("vmc_xyz")
    assert main(["simulate-calibration", path, "-o", str(tmp_path / "p.yaml"), "--knots", "21"]) == 0
    m = load_machine(path)
    values = load_params(str(tmp_path / "p.yaml"), m)
    exx = values["EXX"]
    exact = ExactModel(m)
    for x in np.linspace(-350.0, 350.0, 5):
        only = {"X": x, "Y": 0.0, "Z": -200.0, "EXX": exx}
        dp, _ = exact.error(only)
        assert abs(dp[0] - float(exx(x))) < 1e-9       # +EXX moves the tool by +EXX in x
