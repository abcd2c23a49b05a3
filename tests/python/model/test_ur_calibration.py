"""UR's kinematics calibration file (#41 item 4): read in as errors (import-ur-calibration) and
written out from them (export-urdf --as ur-calibration).

Truth from outside the code: the format as Universal Robots' ROS 2 description defines it
(tests/python/ur_description.py, written from UniversalRobots/Universal_Robots_ROS2_Description's
config/ur5e/default_kinematics.yaml, urdf/inc/ur_common.xacro and urdf/ur_macro.xacro): the URDF
the xacro expands a kinematics file to, and a numpy forward kinematics from the same definition.
chaincomp's model with the errors it reads, and the file it writes read back by yaml and that
numpy model, must agree to 1e-9 mm and 1e-12 rad.
"""

import json
import math

import numpy as np
import pytest
import yaml

from chaincomp import load_machine, load_params
from chaincomp.cli.main import main
from chaincomp.symbolic.numeric import ExactModel

from helpers import ROOT
from ur_description import SEGMENTS, TOOL, UR5E, calibration_text, fk, urdf_text

def calibrated(seed):
    """A factory-calibration-like file: every origin moved by up to 1 mm and 3 mrad, the elbow's
    rotation written the way real calibrations write a near-identity one (pi - a, pi - b, -pi + c)."""
    rng = np.random.default_rng(seed)
    kin = {s: tuple(np.array(v, float) + np.r_[rng.uniform(-1e-3, 1e-3, 3), rng.uniform(-3e-3, 3e-3, 3)])
           for s, v in UR5E.items()}
    x, y, z, *_ = kin["forearm"]
    kin["forearm"] = (x, y, z, math.pi - 0.0024, math.pi - 0.0024, -math.pi + 1e-6)
    return {s: tuple(float(c) for c in v) for s, v in kin.items()}


def cli(capsys, *args):
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.fixture
def arm(tmp_path, capsys):
    urdf = tmp_path / "ur5e.urdf"
    urdf.write_text(urdf_text(UR5E))
    machine = tmp_path / "ur5e.yaml"
    rc, _, err = cli(capsys, "import-urdf", urdf, "--base", "base_link", "--tip", "tool0", "--errors", "origins",
                     "--tool-point", ",".join(map(str, TOOL)), "--tool-direction", "0,0,1", "--tool-reference", "1,0,0",
                     "-o", machine)
    assert rc == 0, err
    return urdf, machine


def worst(machine, values, kin, n=200, seed=4):
    """Largest differences (mm, rad) between chaincomp's model with ``values`` and fk(kin)."""
    m = load_machine(str(machine))
    rng = np.random.default_rng(seed)
    q = rng.uniform(-math.pi, math.pi, (n, 6))
    point, direction, x_axis = ExactModel(m).frame({**values, **{a.name: q[:, i] for i, a in enumerate(m.axes)}})
    far = turn = 0.0
    for k in range(n):
        t = fk(kin, q[k])
        want = (t[:3, :3] @ np.array(TOOL) / 1000 + t[:3, 3]) * 1000
        far = max(far, float(np.abs(np.array([c[k] for c in point]) - want).max()))
        for got, axis in ((direction, 2), (x_axis, 0)):
            turn = max(turn, float(np.abs(np.array([c[k] for c in got]) - t[:3, axis]).max()))
    return far, turn


def test_a_calibration_read_in_is_the_calibrated_arm(tmp_path, capsys, arm):
    urdf, machine = arm
    kin = calibrated(1)
    cal = tmp_path / "calibration.yaml"
    cal.write_text(calibration_text(kin))
    params = tmp_path / "p.yaml"
    rc, out, err = cli(capsys, "import-ur-calibration", machine, urdf, cal, "--base", "base_link", "--tip", "tool0",
                       "-o", params, "--format", "json")
    assert rc == 0, err
    assert json.loads(out)["hash"] == "calib_12788084448423163542"
    values = load_params(str(params), load_machine(str(machine)))
    far, turn = worst(machine, values, kin)
    assert far < 1e-9 and turn < 1e-12, (far, turn)
    # the nominal model is not: the calibration moved the tool by millimetres
    assert worst(machine, {}, kin)[0] > 0.5


def test_the_file_written_is_the_identified_model(tmp_path, capsys, arm):
    urdf, machine = arm
    m = load_machine(str(machine))
    rng = np.random.default_rng(2)
    params = tmp_path / "p.yaml"
    params.write_text(f"machine: {m.name}\nvalues:\n" + "".join(f'  {s.name}: "{rng.uniform(-200, 200):.4f} '
                                                                 f'{s.unit.name}"\n' for s in m.errors))
    out = tmp_path / "calibration.yaml"
    rc, text, err = cli(capsys, "export-urdf", machine, urdf, "--base", "base_link", "--tip", "tool0", "--params",
                        params, "--as", "ur-calibration", "-o", out)
    assert rc == 0, err
    doc = yaml.safe_load(out.read_text())["kinematics"]
    assert set(doc) == set(SEGMENTS) | {"hash"} and not doc["hash"].startswith("calib_")
    kin = {s: tuple(float(doc[s][k]) for k in ("x", "y", "z", "roll", "pitch", "yaw")) for s in SEGMENTS}
    far, turn = worst(machine, load_params(str(params), m), kin)
    assert far < 1e-9 and turn < 1e-12, (far, turn)
    # and read in again, the same errors' pose
    again = tmp_path / "again.yaml"
    rc, _, err = cli(capsys, "import-ur-calibration", machine, urdf, out, "--base", "base_link", "--tip", "tool0",
                     "-o", again)
    assert rc == 0, err
    far, turn = worst(machine, load_params(str(again), m), kin)
    assert far < 1e-9 and turn < 1e-12, (far, turn)


@pytest.mark.parametrize("edit, field, words", [
    (lambda t: t.replace("  wrist_3:", "  wrist_9:"), "kinematics.wrist_9", "unknown entry 'wrist_9'"),
    (lambda t: t.replace("    yaw: 0\n", "    yaw: abc\n", 1), "kinematics.shoulder.yaw", "expected a finite number"),
    (lambda t: t.replace("    x: -0.425", "    x: -425.0"), "kinematics.forearm.x", "-425.0 is beyond 10 m"),
    (lambda t: t.replace("    z: 0.1625\n", ""), "kinematics.shoulder.z", "missing 'z'"),
])
def test_a_bad_calibration_is_refused(tmp_path, capsys, arm, edit, field, words):
    urdf, machine = arm
    cal = tmp_path / "c.yaml"
    cal.write_text(edit(calibration_text({s: tuple(v) for s, v in UR5E.items()})))
    rc, _, err = cli(capsys, "import-ur-calibration", machine, urdf, cal, "--base", "base_link", "--tip", "tool0",
                     "-o", tmp_path / "p.yaml")
    assert rc == 2 and f"{cal}:" in err and f": {field}: {words}" in err and err.count("\n") == 1, err
    assert not (tmp_path / "p.yaml").exists()


def test_a_calibration_read_in_the_old_number_spelling(tmp_path, capsys, arm):
    """'1e-05' is text to YAML 1.1 (xacro's loader); xacro puts the text into the origin, which URDF reads
    as the number: so is it read here."""
    urdf, machine = arm
    kin = {s: tuple(v) for s, v in UR5E.items()}
    cal = tmp_path / "c.yaml"
    cal.write_text(calibration_text(kin).replace("    x: 0\n", "    x: 1e-05\n", 1))
    kin["shoulder"] = (1e-05, *kin["shoulder"][1:])
    rc, _, err = cli(capsys, "import-ur-calibration", machine, urdf, cal, "--base", "base_link", "--tip", "tool0",
                     "-o", tmp_path / "p.yaml")
    assert rc == 0, err
    far, _ = worst(machine, load_params(str(tmp_path / "p.yaml"), load_machine(str(machine))), kin, n=20)
    assert far < 1e-9


def test_other_forms_are_refused(tmp_path, capsys, arm):
    urdf, machine = arm
    # a machine without origin blocks cannot hold a calibration
    offsets = tmp_path / "offsets.yaml"
    assert cli(capsys, "import-urdf", urdf, "--base", "base_link", "--tip", "tool0", "--errors", "joint-offsets",
               "-o", offsets)[0] == 0
    cal = tmp_path / "c.yaml"
    cal.write_text(calibration_text(calibrated(3)))
    rc, _, err = cli(capsys, "import-ur-calibration", offsets, urdf, cal, "--base", "base_link", "--tip", "tool0",
                     "-o", tmp_path / "p.yaml")
    assert rc == 2 and "import the URDF with --errors origins" in err, err
    # a URDF of another form (example-robot-data's UR5: joints about y) has no UR kinematics file
    old = f"{ROOT}/.venv/lib/python3.11/site-packages/cmeel.prefix/share/example-robot-data/robots/ur_description/" \
          "urdf/ur5_robot.urdf"
    m = tmp_path / "old.yaml"
    assert cli(capsys, "import-urdf", old, "--base", "base_link", "--tip", "ee_link", "--errors", "origins",
               "-o", m)[0] == 0
    p = tmp_path / "zero.yaml"
    p.write_text("machine: ur5\nvalues:\n  shoulder_pan_joint_dx: 1 um\n")
    rc, _, err = cli(capsys, "export-urdf", m, old, "--base", "base_link", "--tip", "ee_link", "--params", p,
                     "--as", "ur-calibration", "-o", tmp_path / "out.yaml")
    assert rc == 2 and "six revolute joints each turning about its z" in err and err.count("\n") == 1, err
    assert not (tmp_path / "out.yaml").exists()
