"""``chaincomp protocol --poses N`` for arms: poses that maximise an observability index.

The truth is this file's own: the arm's forward kinematics as textbook standard
Denavit-Hartenberg link matrices with the errors added to the parameters, the identification
Jacobian by central differences, its columns scaled to unit rms over a reference set of
random poses drawn here, projected on the combinations that reference set identifies, and the
indices (smallest singular value; Borm & Menq's O1 = (s1...sr)^(1/r)/sqrt(N)) computed with
numpy. The chosen poses must beat random sets of the same size drawn here.
"""

import json
import math

import numpy as np
import pytest

from arm_models import UR5_A, UR5_ALPHA, UR5_D, dh_chain
from helpers import ROOT, cli, run_cli

UR5_FILE = f"{ROOT}/tools/bench_machines/ur5.yaml"
UR5 = {"d": UR5_D, "a": UR5_A, "alpha": UR5_ALPHA, "tool": [30.0, 0.0, 120.0], "limits": [(-360.0, 360.0)] * 6}
ARM3 = {"d": [300.0, 0.0, 0.0], "a": [50.0, 400.0, 250.0], "alpha": [math.pi / 2, 0.0, 0.0],
        "tool": [0.0, 20.0, 60.0], "limits": [(-170.0, 170.0), (-60.0, 120.0), (-140.0, 100.0)]}
ARM3_YAML = """\
name: arm3
description: test arm, three revolute joints in standard DH, every DH parameter with an error
length_unit: mm
rotation_sense: right_hand
error_block_order: txyz
symbols:
  - {name: q1, role: axis, unit: deg, limits: [-170, 170], meaning: joint 1}
  - {name: q2, role: axis, unit: deg, limits: [-60, 120], meaning: joint 2}
  - {name: q3, role: axis, unit: deg, limits: [-140, 100], meaning: joint 3}
chain:
  - {dh: {theta: q1, d: 300, a: 50, alpha: pi/2}, errors: auto}
  - {dh: {theta: q2, d: 0, a: 400, alpha: 0}, errors: auto}
  - {dh: {theta: q3, d: 0, a: 250, alpha: 0}, errors: auto}
tool:
  point: [0, 20, 60]
"""
ARCSEC = math.pi / 648000


def tool_point(arm, q, e):
    """(poses, 3) at q (poses, joints; rad); e: (joints, 4) errors of theta, d, a, alpha (rad, mm)."""
    names = ("dtheta{}", "dd{}", "da{}", "dalpha{}")
    errors = {names[k].format(i + 1): e[i, k] for i in range(len(e)) for k in range(4)}
    t = dh_chain(q.T, arm["d"], arm["a"], arm["alpha"], errors)
    return (t @ np.array([*arm["tool"], 1.0]))[..., :3]


def jacobian(arm, poses_deg, h=1e-6):
    """(poses, 3, 4 joints) by central differences, errors in mm and rad."""
    n = len(arm["d"])
    q = np.radians(np.asarray(poses_deg, float)).reshape(-1, n)
    out = np.zeros((len(q), 3, 4 * n))
    for k in range(4 * n):
        e = np.zeros(4 * n)
        e[k] = h
        out[:, :, k] = (tool_point(arm, q, e.reshape(n, 4)) - tool_point(arm, q, -e.reshape(n, 4))) / (2 * h)
    return out


class Index:
    """The indices of this file, from a reference set of random poses drawn here."""

    def __init__(self, arm, rng, count=1500):
        self.arm = arm
        ref = jacobian(arm, self.random(rng, count))
        self.scale = np.sqrt((ref ** 2).sum(axis=(0, 1)) / count)
        _, s, vt = np.linalg.svd((ref / self.scale).reshape(-1, ref.shape[-1]), full_matrices=False)
        self.rank = int((s > 1e-7 * s[0]).sum())
        self.basis = vt[:self.rank].T

    def random(self, rng, n):
        return np.column_stack([rng.uniform(lo, hi, n) for lo, hi in self.arm["limits"]])

    def __call__(self, poses_deg, which):
        j = (jacobian(self.arm, poses_deg) / self.scale) @ self.basis
        s = np.linalg.svd(j.reshape(-1, self.rank), compute_uv=False)
        if which == "min-sv":
            return s[self.rank - 1]
        return math.exp(np.log(s[:self.rank]).mean()) / math.sqrt(len(poses_deg))


@pytest.fixture(scope="module")
def arm3(tmp_path_factory):
    path = tmp_path_factory.mktemp("arm") / "arm3.yaml"
    path.write_text(ARM3_YAML)
    return str(path)


@pytest.fixture(scope="module")
def indices(arm3):
    rng = np.random.default_rng(20261201)
    return {"ur5": Index(UR5, rng), "arm3": Index(ARM3, rng)}


def design(path, tmp_path, *args):
    out = tmp_path / "poses.csv"
    doc = json.loads(cli("protocol", path, *args, "-o", str(out), "--format", "json").stdout)
    lines = [r for r in out.read_text().splitlines() if not r.startswith("#")]
    header = lines[0].split(",")
    poses = np.array([[float(c) for c in r.split(",")[:len(header) - 3]] for r in lines[1:]])
    return doc, header, poses, out.read_bytes()


def beats_random(index, poses, which, rng, trials=20):
    mine = index(poses, which)
    others = [index(index.random(rng, len(poses)), which) for _ in range(trials)]
    return mine, float(np.median(others))


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_ur5_poses_beat_random_sets(seed, tmp_path, indices):
    index = indices["ur5"]
    doc, header, poses, _ = design(UR5_FILE, tmp_path, "--poses", "30", "--seed", str(seed))
    assert header == ["q1", "q2", "q3", "q4", "q5", "q6", "x", "y", "z"]
    assert poses.shape == (30, 6) and doc["rank"] == index.rank == 21
    lo, hi = np.array(UR5["limits"]).T
    assert ((poses >= lo) & (poses <= hi)).all()
    mine, median = beats_random(index, poses, "min-sv", np.random.default_rng(seed))
    assert mine > 1.05 * median, (mine, median)
    assert doc["ratio"] > 1.05 and doc["value"] == pytest.approx(mine, rel=0.15)


@pytest.mark.slow
@pytest.mark.parametrize("which", ["min-sv", "o1"])
def test_three_joint_arm_is_an_arm_and_its_poses_beat_random_sets(which, arm3, tmp_path, indices):
    index = indices["arm3"]
    for seed in (4, 5):
        # dh joints make it an arm: no --poses needed (the default number of poses)
        doc, header, poses, _ = design(arm3, tmp_path, "--index", which, "--seed", str(seed))
        assert doc["kind"] == "pose design" and doc["index"] == which and len(poses) == doc["poses"] == 50
        lo, hi = np.array(ARM3["limits"]).T
        assert ((poses >= lo) & (poses <= hi)).all()
        assert doc["rank"] == index.rank
        mine, median = beats_random(index, poses, which, np.random.default_rng(seed))
        assert mine > median * (1.05 if which == "min-sv" else 1.01), (seed, mine, median)


@pytest.mark.slow
def test_same_seed_same_file_and_the_file_feeds_identify(arm3, tmp_path):
    doc, _, _, a = design(arm3, tmp_path, "--poses", "12", "--seed", "7")
    b = design(arm3, tmp_path, "--poses", "12", "--seed", "7")[3]
    c = design(arm3, tmp_path, "--poses", "12", "--seed", "8")[3]
    assert a == b and a != c
    poses = tmp_path / "p.csv"
    poses.write_bytes(a)
    meas = tmp_path / "m.csv"
    params = tmp_path / "truth.yaml"
    params.write_text("machine: arm3\nvalues:\n  dtheta2: 20 arcsec\n  da3: 30 um\n  dd1: -15 um\n")
    run_cli("simulate-measurements", arm3, "--setups", str(poses), "--params", str(params), "--noise", "1um",
            "-o", str(meas))
    fit = json.loads(run_cli("identify", arm3, str(meas), "--format", "json").stdout)
    assert fit["setups"] == 12 and fit["rank"] == doc["rank"]


@pytest.mark.parametrize("args, word", [
    (("--poses", "0"), "argument --poses: must be between 1 and 20000"),
    (("--poses", "20001"), "argument --poses: must be between 1 and 20000"),
    (("--poses", "1e3"), "argument --poses: expected an integer"),
    (("--poses", "10", "--index", "max"), "argument --index: invalid choice"),
    (("--poses", "100", "--pool", "50"), "--pool: expected N < POOL <= 50000"),
    (("--poses", "100", "--pool", "50001"), "argument --pool: must be between 2 and 50000"),
    (("--poses", "2"), "--poses 2: 2 poses give 6 coordinates for the 21 combinations"),
    (("--poses", "10", "--angles", "0,90"), "--angles: not with a pose design"),
    (("--poses", "10", "--measure", "x,q"), "--measure: unknown coordinate 'q'"),
    (("--poses", "10", "--measure", "x,x"), "--measure: 'x' named twice"),
    (("--poses", "10", "--set", "q2=400"), "--set q2: 400 deg is outside the axis' limits"),
    (("--poses", "10", "--seed", "-1"), "argument --seed"),
    (("--poses", "10", "-o", UR5_FILE), "is also an input"),
])
def test_bad_options_exit_2(args, word):
    proc = cli("protocol", UR5_FILE, *args, check=False)
    assert proc.returncode == 2 and proc.stdout == "" and "Traceback" not in proc.stderr, proc.stderr
    assert word in proc.stderr and len(proc.stderr.strip().splitlines()) == 1, proc.stderr


@pytest.mark.slow
def test_a_bad_option_exits_2_from_a_process():
    proc = run_cli("protocol", UR5_FILE, "--poses", "2", check=False)   # the others run in this process
    assert proc.returncode == 2 and proc.stdout == "" and "21 combinations" in proc.stderr, proc.stderr


@pytest.mark.slow
def test_text_report_and_held_joint(tmp_path):
    out = tmp_path / "p.csv"
    text = run_cli("protocol", UR5_FILE, "--poses", "25", "--set", "q6=0", "-o", str(out)).stdout
    assert "POSE DESIGN for ur5" in text and "ratio" in text and f"wrote {out}" in text
    rows = [r.split(",") for r in out.read_text().splitlines() if not r.startswith("#")][1:]
    assert len(rows) == 25 and {r[5] for r in rows} == {"0"}
