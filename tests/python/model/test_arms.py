"""The bundled arms (configs/machines/ur5.yaml, panda.yaml: the makers' published DH tables)
against the makers' URDFs as example-robot-data ships them, imported by chaincomp
import-urdf (whose forward kinematics test_import_urdf.py holds against Pinocchio), and
what compensation does on an arm today.

Frame alignment, stated here and tested:
- UR5: UR's URDF (ur_description) has the controller's joint angles but its base_link is
  UR's DH base frame turned by 180 deg about z, and its ee_link (x out of the flange) is DH
  frame 6 (z out of the flange) turned: ee_link's x, y, z are frame 6's z, -x, -y. So
  URDF(q) = Rz(pi) · DH(q) · C with C's columns (0,0,1), (-1,0,0), (0,-1,0): the bundled
  tool point p (frame 6) is C^T p in ee_link.
- Panda: Franka's URDF frames panda_link0 ... panda_link8 are the modified-DH frames and
  the flange: no alignment at all.
The UR5's URDF writes pi/2 as 1.57079632679 (4.9e-12 rad short) in three joint origins: the
two models then differ by at most 3 x 4.9e-12 rad x the reach, ~1.5e-8 mm, and that is the
tolerance of the UR5's comparison; Franka's URDF writes pi/2 to the last digit.
"""

from __future__ import annotations

import csv
import math
import os

import numpy as np
import pytest

from chaincomp import load_machine, load_params
from chaincomp.symbolic.numeric import ExactModel

from arm_models import UR5_A, UR5_D
from helpers import PARAMS, ROOT, machine_path
from helpers import FRAME_ARMS, no_frame_file
from test_import_urdf import ARMS, random_configurations, run

BUILD = os.path.join(ROOT, "build")
E2E_CONFIG = os.path.join(ROOT, "tests", "e2e", "config_test.yaml")
RZ_PI = np.diag([-1.0, -1.0, 1.0])
UR5_TOOL_FRAME = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])  # C: ee_link -> frame 6
URDF_HALF_PI = 1.57079632679


def import_with(tmp_path, arm, tip, point, direction, reference=None):
    urdf, base, _ = ARMS[arm]
    out = tmp_path / f"{arm}-urdf.yaml"
    frame = [] if reference is None else ["--tool-reference", ",".join(repr(float(v)) for v in reference)]
    code, _, err = run("import-urdf", urdf, "--base", base, "--tip", tip, "--tool-point",
                       ",".join(repr(float(v)) for v in point), "--tool-direction",
                       ",".join(repr(float(v)) for v in direction), *frame, "-o", out)
    assert code == 0, err
    return load_machine(str(out))


def poses(machine, q_by_index):
    """Tool point and direction of ``machine`` with its i-th axis at q_by_index[i] (rad)."""
    p, d = ExactModel(machine).pose({a.name: q_by_index[i] for i, a in enumerate(machine.axes)})
    return np.array([np.broadcast_to(c, q_by_index[0].shape) for c in p], float).T, \
        np.array([np.broadcast_to(c, q_by_index[0].shape) for c in d], float).T


def frames(machine, q_by_index):
    """The tool frame's x axis (N x 3) of ``machine`` with its i-th axis at q_by_index[i]."""
    _, _, x = ExactModel(machine).frame({a.name: q_by_index[i] for i, a in enumerate(machine.axes)})
    return np.array([np.broadcast_to(c, q_by_index[0].shape) for c in x], float).T


def test_ur5_equals_urs_urdf_after_the_stated_alignment(tmp_path):
    dh = load_machine(machine_path("ur5"))
    point, direction = np.array(dh.tool_point, float), np.array(dh.tool_direction, float)
    x_axis = np.array(dh.tool_reference, float)       # the bundled frame: DH frame 6 (x6, z6)
    assert np.array_equal(x_axis, [1, 0, 0]) and np.array_equal(direction, [0, 0, 1])
    urdf = import_with(tmp_path, "ur5", "ee_link", UR5_TOOL_FRAME.T @ point, UR5_TOOL_FRAME.T @ direction,
                       UR5_TOOL_FRAME.T @ x_axis)
    assert [a.name for a in urdf.axes] == ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
                                           "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"]
    q = list(random_configurations(dh, 1000, seed=17).values())   # q1..q6 = the URDF's joints 1..6
    p_dh, d_dh = poses(dh, q)
    p_urdf, d_urdf = poses(urdf, q)
    reach = sum(map(abs, UR5_D + UR5_A)) + np.linalg.norm(point)
    bound = 3 * (math.pi / 2 - URDF_HALF_PI) * reach
    assert 1e-9 < bound < 2e-8
    assert np.abs(p_urdf - p_dh @ RZ_PI.T).max() < bound
    assert np.abs(d_urdf - d_dh @ RZ_PI.T).max() < 3 * (math.pi / 2 - URDF_HALF_PI)
    # the frame's x axis too: ee_link's -y (the URDF's own tip orientation) is DH x6 after the base turn
    assert np.abs(frames(urdf, q) - frames(dh, q) @ RZ_PI.T).max() < 3 * (math.pi / 2 - URDF_HALF_PI)
    assert np.abs(frames(urdf, q) - frames(dh, q)).max() > 1     # not by accident either
    # not by accident: without the base rotation they are far apart
    assert np.abs(p_urdf - p_dh).max() > 100


def test_panda_equals_frankas_urdf_frame_for_frame(tmp_path):
    dh = load_machine(machine_path("panda"))
    point, direction = np.array(dh.tool_point, float), np.array(dh.tool_direction, float)
    assert np.array_equal(np.array(dh.tool_reference, float), [1, 0, 0])   # the flange frame, panda_link8
    urdf = import_with(tmp_path, "panda", "panda_link8", point, direction, [1, 0, 0])
    assert [a.name for a in urdf.axes] == [f"panda_joint{i}" for i in range(1, 8)]
    # the bundled limits are Franka's datasheet degrees; the URDF's radians within 0.01 deg of them
    for a, b in zip(dh.axes, urdf.axes):
        assert np.allclose(a.limits, b.limits, atol=0.01), (a.name, a.limits, b.limits)
    q = list(random_configurations(dh, 1000, seed=19).values())
    p_dh, d_dh = poses(dh, q)
    p_urdf, d_urdf = poses(urdf, q)
    assert np.abs(p_urdf - p_dh).max() < 1e-9
    assert np.abs(d_urdf - d_dh).max() < 1e-12
    assert np.abs(frames(urdf, q) - frames(dh, q)).max() < 1e-12


# ---------------------------------------------------------------- compensation today

@pytest.mark.slow
@pytest.mark.parametrize("arm", ["panda", "ur5"])
def test_compensation_of_an_arm_holds_point_and_direction_or_reports_the_residual(arm, tmp_path):
    """What chaincompd / replay do on an arm without a tool frame (with one, the next test):
    the tool point and the tool direction are corrected (5 conditions; a six-joint arm has one
    joint combination left, a seven-joint arm two, and the least-squares step takes the
    smallest correction, leaving the turn about the tool axis free); every command is either
    corrected (status 0: the exact chain at the corrected joints puts the point within 1e-6
    mm and the direction within 1e-9 rad of the nominal) or reported (status 1, residual:
    near a singular pose, with each correction within its bound) with the residual the
    exact chain leaves. Never another status, never a correction beyond 1 degree."""
    if not os.path.isfile(os.path.join(BUILD, "bin", "chaincomp_replay")):
        pytest.skip("no C++ build (tools/setup)")
    path = str(no_frame_file(tmp_path, arm))     # the bundled arm without its tool frame
    m = load_machine(path)
    params = os.path.join(PARAMS, f"{arm}-demo.yaml")
    log, out = tmp_path / "arm.lcmlog", tmp_path / "replay.csv"
    code, _, err = run("simulate-log", path, "-o", log, "--seconds", "0.2")
    assert code == 0, err
    code, _, err = run("replay", path, log, "--params", params, "--config", E2E_CONFIG,
                       "--csv", out)
    assert code == 0, err
    with open(out) as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 200 and {r["status"] for r in rows} <= {"0", "1"}
    deg = math.pi / 180
    cmd = [np.array([float(r[f"commanded_{a.name}_deg"]) * deg for r in rows]) for a in m.axes]
    cor = [np.array([float(r[f"corrected_{a.name}_deg"]) * deg for r in rows]) for a in m.axes]
    assert max(np.abs(c - k).max() for c, k in zip(cor, cmd)) <= 0.0175 + 1e-12   # kMaxAngularCorrection
    values = load_params(params, m)
    exact = ExactModel(m)
    p_nom, d_nom = exact.pose({a.name: cmd[i] for i, a in enumerate(m.axes)})
    p_act, d_act = exact.pose({**values, **{a.name: cor[i] for i, a in enumerate(m.axes)}})
    miss = np.linalg.norm(np.array(p_act) - np.array(p_nom), axis=0)
    tilt = np.linalg.norm(np.array(d_act) - np.array(d_nom), axis=0)
    ok = np.array([r["status"] == "0" for r in rows])
    assert ok.sum() >= 100, ok.sum()   # most of the path is away from singular poses
    assert miss[ok].max() < 1e-6 and tilt[ok].max() < 1e-9
    reported = np.array([float(r["residual_point_mm"]) for r in rows])
    assert np.allclose(miss[~ok], reported[~ok], rtol=1e-6, atol=1e-10)


@pytest.mark.slow
@pytest.mark.parametrize("arm", ["panda", "ur5"])
def test_replay_of_an_arm_with_a_tool_frame_corrects_point_and_orientation(arm, tmp_path):
    """The same through replay with the arm's tool given a frame (tests/python/
    test_arm_compensation.py: the variants and numpy models): position and full orientation
    (six conditions; the Panda's seventh joint takes the smallest correction). Every command
    corrected (status 0: the numpy arm at the corrected joints within 1e-6 mm and 1e-9 rad of
    the nominal frame) or reported (status 1, near the singular poses the simulated path
    starts from) with each correction within its bound and the residual the numpy arm leaves."""
    if not os.path.isfile(os.path.join(BUILD, "bin", "chaincomp_replay")):
        pytest.skip("no C++ build (tools/setup)")
    from scipy.spatial.transform import Rotation
    write, numpy_arm = FRAME_ARMS[arm]
    path = write(tmp_path)
    m = load_machine(str(path))
    params = os.path.join(PARAMS, f"{arm}-demo.yaml")
    log, out = tmp_path / "arm.lcmlog", tmp_path / "replay.csv"
    code, _, err = run("simulate-log", path, "-o", log, "--seconds", "0.2")
    assert code == 0, err
    code, _, err = run("replay", path, log, "--params", params, "--config", E2E_CONFIG, "--csv", out)
    assert code == 0, err
    with open(out) as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 200 and {r["status"] for r in rows} <= {"0", "1"}
    deg = math.pi / 180
    cmd = np.array([[float(r[f"commanded_{a.name}_deg"]) * deg for a in m.axes] for r in rows])
    cor = np.array([[float(r[f"corrected_{a.name}_deg"]) * deg for a in m.axes] for r in rows])
    assert np.abs(cor - cmd).max() <= 0.0175 + 1e-12   # kMaxAngularCorrection
    values = load_params(params, m)
    R1, p1 = numpy_arm(cor, {s.name: values.get(s.name, 0.0) for s in m.errors})
    R0, p0 = numpy_arm(cmd)
    miss = np.linalg.norm(p1 - p0, axis=1)
    angle = np.linalg.norm(Rotation.from_matrix(R1 @ np.swapaxes(R0, -1, -2)).as_rotvec(), axis=1)
    ok = np.array([r["status"] == "0" for r in rows])
    assert ok.sum() >= 100, ok.sum()
    assert miss[ok].max() < 1e-6 and angle[ok].max() < 1e-9
    reported = np.array([[float(r["residual_point_mm"]), float(r["residual_direction_rad"])] for r in rows])
    assert np.allclose(miss[~ok], reported[~ok, 0], rtol=1e-6, atol=1e-10)
    assert np.allclose(angle[~ok], reported[~ok, 1], rtol=1e-2, atol=1e-10)
