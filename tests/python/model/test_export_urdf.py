"""export-urdf (#41 item 4): a calibrated URDF out of an imported machine and its identified
errors. The truth is Pinocchio reading the written URDF: its tool frame must equal chaincomp's
exact model of the imported machine with those errors, for every error kind at once (zero offsets
and 6-DOF origin blocks, --errors all) on two arms of example-robot-data."""

import numpy as np
import pytest

from chaincomp.model.machine import load_machine
from chaincomp.model.params import load_params
from chaincomp.symbolic.numeric import ExactModel

from test_import_urdf import ARMS, TOOL, imported, pin, pinocchio_tips, random_configurations, run, with_direction


def _params(tmp_path, machine, seed):
    """Every error at a random value of up to 200 um or 200 arcsec (a real calibration's size)."""
    rng = np.random.default_rng(seed)
    lines = [f"machine: {machine.name}", "values:"]
    lines += [f"  {s.name}: {rng.uniform(-200, 200):.4f} {s.unit.name}" for s in machine.errors]
    path = tmp_path / "p.yaml"
    path.write_text("\n".join(lines) + "\n")
    return str(path)


@pytest.mark.parametrize("arm", sorted(ARMS))
def test_the_calibrated_urdf_is_the_identified_model(arm, tmp_path):
    urdf, base, tip = ARMS[arm]
    path = imported(tmp_path, arm, "all")
    m = load_machine(path)
    params = _params(tmp_path, m, seed=5)
    out = tmp_path / "calibrated.urdf"
    code, stdout, err = run("export-urdf", path, urdf, "--base", base, "--tip", tip, "--params", params, "-o", out)
    assert code == 0, err
    assert "wrote" in stdout
    values = load_params(params, m)
    q = random_configurations(m, 300, seed=9)
    point, _ = ExactModel(m).pose({**values, **q})
    frames = [ExactModel(with_direction(m, d)).pose({**values, **q})[1] for d in ((1, 0, 0), (0, 1, 0), (0, 0, 1))]
    model = pin.buildModelFromUrdf(str(out))
    data = model.createData()
    worst_point = worst_angle = 0.0
    for k, rel, want_point in pinocchio_tips(model, data, m, q, base, tip):
        worst_point = max(worst_point, np.abs(np.array([c[k] for c in point]) - want_point).max())
        got_rotation = np.array([[c[k] for c in axis] for axis in frames]).T
        worst_angle = max(worst_angle, np.linalg.norm(pin.log3(rel.rotation.T @ got_rotation)))
    assert worst_point < 1e-9 and worst_angle < 1e-12, (worst_point, worst_angle)
    # the errors moved the tool: the calibrated file is not the original
    original = pin.buildModelFromUrdf(urdf)
    moved = max(np.abs(want - ref).max() for (_, _, want), (_, _, ref) in
                zip(pinocchio_tips(model, data, m, q, base, tip),
                    pinocchio_tips(original, original.createData(), m, q, base, tip)))
    assert moved > 0.1, moved   # mm
    # everything but the moving joints' origins is kept (the links, the fixed joints, the limits)
    before, after = open(urdf).read().splitlines(), out.read_text().splitlines()
    assert sum("<link" in t for t in before) == sum("<link" in t for t in after)
    assert sum("<limit" in t for t in before) == sum("<limit" in t for t in after)


def test_a_machine_of_another_path_is_refused(tmp_path):
    urdf, base, tip = ARMS["ur5"]
    path = imported(tmp_path, "ur5", "all")
    params = _params(tmp_path, load_machine(path), seed=6)
    # a path a joint short, and one ending a fixed joint short (the same axes, another tool pose):
    # neither is what the machine file was imported from
    for args, words in ((("--base", "shoulder_link", "--tip", tip), "not the path it was imported from"),
                        (("--base", base, "--tip", "wrist_3_link"), "is MACHINE.yaml imported from this URDF")):
        code, _, err = run("export-urdf", path, urdf, *args, "--params", params, "-o", tmp_path / "c.urdf")
        assert code == 2 and words in err, err
        assert not (tmp_path / "c.urdf").exists()
    # a table cannot go into an origin
    m = load_machine(path)
    axis = m.axes[0]
    table = tmp_path / "t.yaml"
    table.write_text(f"machine: {m.name}\nvalues:\n  {m.errors[0].name}:\n    axis: {axis.name}\n"
                     f"    units: [deg, {m.errors[0].unit.name}]\n    interpolation: linear\n    outside: hold\n    table:\n      - [-90, 0]\n      - [90, 1]\n")
    code, _, err = run("export-urdf", path, urdf, "--base", base, "--tip", tip, "--params", table,
                       "-o", tmp_path / "c.urdf")
    assert code == 2 and "cannot go into a URDF origin" in err, err
    assert not (tmp_path / "c.urdf").exists()
