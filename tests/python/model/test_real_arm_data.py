"""Real arm data through the loop (#41 item 7): measured by others, read from tests/data/arms/ (its
README gives each file's source, commit, licence and citation).

1. Three factory calibrations that UR controllers gave (ur_calibration's YAML, two UR3e and a
   UR5e), read in with import-ur-calibration and written back with export-urdf --as
   ur-calibration. Truth: the format's definition, as tests/python/ur_description.py writes it
   (a numpy forward kinematics of the xacro's meaning).
2. A Franka Panda's joint readings with a ball held in one socket of a printed tool, 30 poses each
   for two sockets 50 mm apart (platonics-delft/kinematics_calibration). The ball's place is the
   same at every pose of a socket: import-urdf -> identify (x y z = 0: the socket is where the
   instrument's frame is, the base block carries where that is) -> export-urdf. Truth: that
   physical fact, the printed tool's 50 mm (its README: a caliper finds it within 0.1 mm), and
   Franka's published modified-DH table (tests/python/arm_models.py), a model chaincomp never
   sees; the second socket's poses are held out of the fit.
"""

import contextlib
import csv
import io
import json
import math
import os
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import yaml

from chaincomp import load_machine, load_params
from chaincomp.cli.main import main
from chaincomp.symbolic.numeric import ExactModel

from arm_models import panda
from helpers import ROOT
from ur_description import SEGMENTS, TOOL, UR3E, UR5E, fk, urdf_text

DATA = os.path.join(ROOT, "tests", "data", "arms")
PANDA_URDF = os.path.join(ROOT, ".venv", "lib", "python3.11", "site-packages", "cmeel.prefix", "share",
                          "example-robot-data", "robots", "panda_description", "urdf", "panda.urdf")
BALL = 133.5   # mm past panda_link8 along z: the nominal ball of the data's own URDF (hand 103.4 + 30.1)
# the fit: a point measured at one place cannot see a turn of the whole arm about it (base_e*,
# joint 1's zero), a turn about the axis through the ball (joint 7's zero) nor the tool block's
# turns (a point on its axis: its translations carry them)
HELD = "base_ex,base_ey,base_ez,tool_ex,tool_ey,tool_ez,panda_joint1_zero,panda_joint7_zero"


def cli(capsys, *args):
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def read_kinematics(path):
    doc = yaml.safe_load(open(path))["kinematics"]
    return {s: tuple(float(doc[s][k]) for k in ("x", "y", "z", "roll", "pitch", "yaw")) for s in SEGMENTS}


def worst(machine, values, kin, n=60, seed=5):
    """Largest differences (mm, rad) between chaincomp's model with ``values`` and fk(kin)."""
    m = load_machine(str(machine))
    q = np.random.default_rng(seed).uniform(-math.pi, math.pi, (n, 6))
    point, direction, x_axis = ExactModel(m).frame({**values, **{a.name: q[:, i] for i, a in enumerate(m.axes)}})
    far = turn = 0.0
    for k in range(n):
        t = fk(kin, q[k])
        want = t[:3, :3] @ np.array(TOOL) + t[:3, 3] * 1000
        far = max(far, float(np.abs(np.array([c[k] for c in point]) - want).max()))
        for got, axis in ((direction, 2), (x_axis, 0)):
            turn = max(turn, float(np.abs(np.array([c[k] for c in got]) - t[:3, axis]).max()))
    return far, turn


@pytest.mark.parametrize("name, nominal", [("alice_ur3e", UR3E), ("bob_ur3e", UR3E), ("husky_ur5e", UR5E)])
def test_a_real_ur_calibration_goes_in_and_comes_back_out(tmp_path, capsys, name, nominal):
    cal = os.path.join(DATA, "ur-calibrations", f"{name}_calibration.yaml")
    real = read_kinematics(cal)
    urdf, machine, params = tmp_path / "ur.urdf", tmp_path / "ur.yaml", tmp_path / "factory.yaml"
    urdf.write_text(urdf_text(nominal))   # the description as the xacro expands it for the robot's type
    rc, _, err = cli(capsys, "import-urdf", urdf, "--base", "base_link", "--tip", "tool0", "--errors", "origins",
                     "--tool-point", ",".join(map(str, TOOL)), "--tool-direction", "0,0,1", "--tool-reference", "1,0,0",
                     "-o", machine)
    assert rc == 0, err
    rc, out, err = cli(capsys, "import-ur-calibration", machine, urdf, cal, "--base", "base_link", "--tip", "tool0",
                       "-o", params, "--format", "json")
    assert rc == 0, err
    assert json.loads(out)["hash"] == yaml.safe_load(open(cal))["kinematics"]["hash"]
    m = load_machine(str(machine))
    values = load_params(str(params), m)
    far, turn = worst(machine, values, real)
    assert far < 1e-9 and turn < 1e-12, (far, turn)
    # the factory's numbers matter: the nominal model misses the calibrated arm by millimetres
    assert worst(machine, {}, real)[0] > 1.0
    # and back out, for UR's driver: the same arm
    back = tmp_path / "back.yaml"
    rc, _, err = cli(capsys, "export-urdf", machine, urdf, "--base", "base_link", "--tip", "tool0", "--params", params,
                     "--as", "ur-calibration", "-o", back)
    assert rc == 0, err
    far, turn = worst(machine, values, read_kinematics(back))
    assert far < 1e-9 and turn < 1e-12, (far, turn)


def joint_readings(hole):
    return np.loadtxt(os.path.join(DATA, "panda-platonics", f"front_{hole}.csv"), delimiter=",")   # rad, N x 7


def ball_points(q, values):
    """The ball's centre (mm, N x 3) by Franka's DH table with the identified zero offsets and tool."""
    e = {f"dtheta{j}": values.get(f"panda_joint{j}_zero", 0.0) for j in range(1, 8)}
    ball = np.array([values.get("tool_dx", 0.0), values.get("tool_dy", 0.0), BALL + values.get("tool_dz", 0.0)])
    t = panda(q.T, e)
    return t[:, :3, :3] @ ball + t[:, :3, 3]


def spread(points):
    """RMS distance (mm) of the points from their mean: zero for a ball that never moved."""
    return float(np.sqrt(((points - points.mean(0)) ** 2).sum(1).mean()))


def urdf_link_frame(path, tip, q):
    """The tip link's frame in the root link (4 x 4, mm) at joint angles q {name: rad}: the URDF's
    origins (R = Rz(yaw) Ry(pitch) Rx(roll)) and revolute motions about each joint's axis."""
    def rpy_xyz(o):
        r, p, y = (float(v) for v in o.get("rpy", "0 0 0").split())
        m = np.eye(4)
        cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
        m[:3, :3] = (np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]]) @ np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
                     @ np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]]))
        m[:3, 3] = [1000 * float(v) for v in o.get("xyz", "0 0 0").split()]
        return m
    joints = {j.find("child").get("link"): j for j in ET.parse(path).getroot().iter("joint")}
    chain, link = [], tip
    while link in joints:
        chain.append(joints[link])
        link = joints[link].find("parent").get("link")
    t = np.eye(4)
    for j in reversed(chain):
        t = t @ rpy_xyz(j.find("origin").attrib)
        if j.get("type") == "revolute":
            k = np.array([float(v) for v in j.find("axis").get("xyz").split()])
            a, kx = q[j.get("name")], np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
            turn = np.eye(4)
            turn[:3, :3] = np.eye(3) + math.sin(a) * kx + (1 - math.cos(a)) * kx @ kx   # Rodrigues
            t = t @ turn
    return t


@pytest.fixture(scope="module")
def panda_fit(tmp_path_factory):
    """import-urdf -> identify on the first socket's poses: the files and identify's JSON."""
    work = tmp_path_factory.mktemp("panda")
    machine, measured, params = work / "panda.yaml", work / "hole_0.csv", work / "identified.yaml"
    assert main(["import-urdf", PANDA_URDF, "--base", "panda_link0", "--tip", "panda_link8", "--errors",
                 "joint-offsets,tool,base", "--tool-point", f"0,0,{BALL}", "-o", str(machine)]) == 0
    with open(measured, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow([f"panda_joint{j}" for j in range(1, 8)] + ["x", "y", "z"])
        w.writerows([f"{math.degrees(v):.12g}" for v in row] + [0, 0, 0] for row in joint_readings("hole_0"))
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["identify", str(machine), str(measured), "--assume-zero", HELD, "--sigma", "100um",
                     "--format", "json", "-o", str(params)]) == 0
    return work, machine, measured, params, json.loads(out.getvalue())


def test_a_real_fixed_point_data_set_calibrates_a_panda(panda_fit, capsys):
    work, machine, measured, params, fit = panda_fit
    assert fit["converged"]
    m = load_machine(str(machine))
    values = load_params(str(params), m)   # the registration is written as zero: not a machine error
    assert all(values[f"base_d{c}"] == 0 for c in "xyz")
    socket = np.array([-fit["registration"][f"base_d{c}"]["value"] for c in "xyz"])

    # Franka's own table with the fitted values puts the ball where identify says, at every pose
    train = ball_points(joint_readings("hole_0"), values)
    assert np.sqrt(((train - socket) ** 2).mean()) == pytest.approx(fit["rms_residual"], rel=1e-6)
    # nominal: the ball wanders by centimetres; calibrated: by under 0.6 mm (fitted), 1.2 mm (held out)
    nominal = {}
    before = [spread(ball_points(joint_readings(h), nominal)) for h in ("hole_0", "hole_1")]
    after = [spread(ball_points(joint_readings(h), values)) for h in ("hole_0", "hole_1")]
    assert min(before) > 8.0 and after[0] < 0.6 and after[1] < 1.2, (before, after)
    # the two sockets of the printed tool are 50 mm apart: nominal 2 mm off, calibrated under 1 mm
    gap = [float(np.linalg.norm(ball_points(joint_readings("hole_0"), v).mean(0)
                                - ball_points(joint_readings("hole_1"), v).mean(0))) for v in (nominal, values)]
    assert abs(gap[0] - 50.0) > 1.5 and abs(gap[1] - 50.0) < 1.0, gap
    # honest: 100 um per coordinate is more than a joint-offset model can reach on this arm, and
    # identify says so, naming set-ups; no reading is an outlier by far (the misfit is the model's)
    assert fit["misfit"] and "the largest residuals: line " in fit["misfit"]
    rc, out, err = cli(capsys, "identify", machine, measured, "--assume-zero", HELD, "--sigma", "100um",
                       "--loss", "huber", "--format", "json", "-o", work / "huber.yaml")
    assert rc == 0, err
    worst_reading = max(abs(o["standardized_residual"]) for o in json.loads(out)["outliers"])
    assert 3 < worst_reading < 10, worst_reading


def test_the_calibrated_panda_urdf_is_the_identified_arm(panda_fit, capsys):
    work, machine, measured, params, _ = panda_fit
    calibrated = work / "panda-calibrated.urdf"
    rc, out, err = cli(capsys, "export-urdf", machine, PANDA_URDF, "--base", "panda_link0", "--tip", "panda_link8",
                       "--params", params, "--format", "json", "-o", calibrated)
    assert rc == 0, err
    values = load_params(str(params), load_machine(str(machine)))
    # the tool mount has no joint origin to go into (the registration is zero in the params)
    assert sorted(json.loads(out)["left_out"]) == sorted(k for k, v in values.items()
                                                         if k.startswith(("tool_", "base_")) and v)
    e = {f"dtheta{j}": values[f"panda_joint{j}_zero"] for j in range(1, 8)}
    for q in joint_readings("hole_1")[::3]:
        got = urdf_link_frame(calibrated, "panda_link8", {f"panda_joint{j}": q[j - 1] for j in range(1, 8)})
        want = panda(q[:, None], e)[0]
        assert np.abs(got[:3, 3] - want[:3, 3]).max() < 1e-9 and np.abs(got[:3, :3] - want[:3, :3]).max() < 1e-12
