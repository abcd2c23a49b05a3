"""tools/demo-arm (issue #17, done-when: the UR5 calibrated and compensated from simulated
tracker data), run as a user runs it, its figures recomputed here with an independent numpy
model of the UR5: Universal Robots' published standard-DH table written out below, with the
configs/machines/ur5.yaml error layout (four DH errors per joint, none for d3 and d4, Hayati
tilts about y after joints 2 and 3) and the tracker target 40 mm off the flange axis,
100 mm out. Params files are read here by their "VALUE UNIT" text, not by chaincomp.
"""

from __future__ import annotations

import csv
import json
import math
import os
import re
import subprocess

import numpy as np
import pytest
import yaml

from arm_models import ur5
from helpers import ROOT

DEMO = os.path.join(ROOT, "tools", "demo-arm")
PARAMS = os.path.join(ROOT, "configs", "params", "ur5-demo.yaml")
TOOL = np.array([40.0, 0.0, 100.0, 1.0])
UNITS = {"um": 1e-3, "arcsec": math.pi / (180 * 3600)}   # to mm and rad
NOISE = 0.020   # mm: the demo's --noise 20um


def read_values(path):
    """Error values of a params file in mm and rad, read from their text."""
    with open(path) as f:
        values = yaml.safe_load(f)["values"]
    out = {}
    for name, text in values.items():
        number, unit = str(text).split()
        out[name] = float(number) * UNITS[unit]
    return out


def ur5_point(q, e=None, tool=TOOL):
    """Tool point (N x 3, mm) at joint angles q (N x 6, rad) with errors e (name -> mm | rad)."""
    return (ur5(q.T, e, betas=(2, 3)) @ tool)[:, :3]


def read_csv(path):
    with open(path) as f:
        return list(csv.DictReader(line for line in f if not line.startswith("#")))


def joints(rows, fmt="q{}"):
    return np.radians([[float(r[fmt.format(n)]) for n in range(1, 7)] for r in rows])


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    if not os.path.isfile(os.path.join(ROOT, "build", "bin", "chaincomp_replay")):
        pytest.skip("no C++ build (tools/setup)")
    work = tmp_path_factory.mktemp("demo-arm")
    done = subprocess.run([DEMO, "--no-setup", "--work", str(work)], cwd=ROOT, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    return work, done.stdout + done.stderr


@pytest.mark.slow
def test_the_numpy_model_is_the_bundled_ur5(demo):
    """The simulated tracker readings are the true tool points plus 20 um of noise: the
    model here agrees with chaincomp's to 1e-9 mm at the held-out poses (no noise), and
    the readings scatter about it as 20 um noise does."""
    work, _ = demo
    true = read_values(PARAMS)
    held = read_csv(work / "held-out.csv")
    measured = np.array([[float(r[c]) for c in "xyz"] for r in held])
    assert np.abs(ur5_point(joints(held), true) - measured).max() < 1e-9
    tracker = read_csv(work / "tracker.csv")
    noise = np.array([[float(r[c]) for c in "xyz"] for r in tracker]) - ur5_point(joints(tracker), true)
    assert len(tracker) == 50 and 0.8 * NOISE < noise.std() < 1.2 * NOISE


@pytest.mark.slow
def test_the_urdf_import_step(demo):
    """The demo's import of UR's URDF is the DH model turned by 180 deg about z (UR's
    base_link; tests/python/model/test_arms.py), ee_link's origin on flange frame 6's, and each
    joint's zero offset adds to its angle. The URDF writes pi/2 as 1.57079632679: 2e-8 mm."""
    from chaincomp import load_machine
    from chaincomp.symbolic.numeric import ExactModel
    work, out = demo
    assert "ur5: no findings" in out
    machine = load_machine(str(work / "ur5-urdf.yaml"))
    assert len(machine.axes) == 6
    zeros = [f"{a.name}_zero" for a in machine.axes]
    assert sorted(s.name for s in machine.symbols if s.role == "error") == sorted(zeros)
    rng = np.random.default_rng(5)
    q = rng.uniform(-math.pi, math.pi, (200, 6))
    offsets = rng.uniform(-1e-3, 1e-3, 6)
    values = {a.name: q[:, i] for i, a in enumerate(machine.axes)}
    values.update(zip(zeros, offsets))
    point, _ = ExactModel(machine).pose(values)
    flange = ur5_point(q + offsets, {}, tool=np.array([0.0, 0.0, 0.0, 1.0]))
    rz_pi = np.diag([-1.0, -1.0, 1.0])
    assert np.abs(np.array(point, float).T - flange @ rz_pi.T).max() < 2e-8


def test_calibration_makes_the_held_out_error_20_times_smaller(demo):
    work, out = demo
    true = read_values(PARAMS)
    identified = read_values(work / "ur5-identified.yaml")
    held = read_csv(work / "held-out.csv")
    assert len(held) == 50
    q = joints(held)
    truth = ur5_point(q, true)
    before = np.linalg.norm(ur5_point(q) - truth, axis=1)
    after_xyz = ur5_point(q, identified) - truth
    after = np.linalg.norm(after_xyz, axis=1)
    rms = lambda v: math.sqrt(np.mean(v ** 2))
    assert 0.2 < before.max() < 5   # the nominal model misses by tenths of a mm to mm
    assert rms(before) >= 20 * rms(after) and before.max() >= 20 * after.max()
    assert np.abs(after_xyz).max() < 3 * NOISE   # predictions within 3 sigma of the noise
    # the rank the demo's identify reports is that of the numpy model's Jacobian (central
    # differences, columns scaled to unit norm) at the designed poses
    poses = joints(read_csv(work / "poses.csv"))
    names = list(true)
    h = 1e-6
    jac = np.stack([(ur5_point(poses, {n: h}) - ur5_point(poses, {n: -h})).ravel() / (2 * h) for n in names], 1)
    sv = np.linalg.svd(jac / np.linalg.norm(jac, axis=0), compute_uv=False)
    rank = int((sv > 1e-6 * sv[0]).sum())
    assert sv[rank - 1] > 1e3 * sv[rank:].max()   # a clear gap, not a threshold's accident
    assert re.search(rf"the data see {rank} independent combinations", out), out
    assert rank == len(names) - 1
    # and the figures the demo printed are these
    with open(work / "held-out.json") as f:
        fig = json.load(f)
    assert np.allclose([fig["before_max_mm"], fig["before_rms_mm"], fig["after_max_mm"], fig["after_rms_mm"]],
                       [before.max(), rms(before), after.max(), rms(after)], rtol=1e-6, atol=1e-9)


@pytest.mark.slow
def test_compensation_with_the_identified_values(demo):
    """Through replay (the daemon's compensator), against the true errors. With the default
    config, every command replay reports corrected puts the identified model's tool point on
    the nominal one (1e-6 mm), so the true arm is off only by what calibration left (within
    3 sigma of the noise, 20x less than without); every other command carries the residual
    the identified model leaves. Without the ramp and the rate limit, that holds for every
    command's point; and with the default config no command is further off than without
    compensation."""
    work, _ = demo
    true = read_values(PARAMS)
    identified = read_values(work / "ur5-identified.yaml")
    with open(work / "compensation.json") as f:
        fig = json.load(f)
    rms = lambda v: math.sqrt(np.mean(v ** 2))
    miss = {}
    for name in ("replay.csv", "replay-no-rate-limit.csv"):
        with open(work / name) as f:
            rows = list(csv.DictReader(f))
        assert len(rows) == 10000
        cmd, cor = joints(rows, "commanded_q{}_deg"), joints(rows, "corrected_q{}_deg")
        nominal = ur5_point(cmd)
        ok = np.array([r["status"] == "0" for r in rows])
        assert {r["status"] for r in rows} <= {"0", "1"} and ok.mean() > 0.8
        model_miss = np.linalg.norm(ur5_point(cor, identified) - nominal, axis=1)
        assert model_miss[ok].max() < 1e-6
        reported = np.array([float(r["residual_point_mm"]) for r in rows])
        assert np.allclose(model_miss[~ok], reported[~ok], rtol=1e-6, atol=1e-9)
        miss[name] = np.linalg.norm(ur5_point(cor, true) - nominal, axis=1), ok
    without = np.linalg.norm(ur5_point(cmd, true) - nominal, axis=1)
    with_, ok = miss["replay.csv"]
    assert with_[ok].max() < 3 * NOISE and without.max() >= 20 * with_[ok].max()
    free, _ = miss["replay-no-rate-limit.csv"]
    assert free.max() < 3 * NOISE
    # Near the singular passes the daemon publishes, of what the rate limit allows, a target
    # never further off than no correction (issue #17): at every command, against the truth.
    assert np.all(with_ <= without)
    assert fig["default_worse_than_without"] == 0
    # Without the rate limit the correction is continuous (tests/cpp/test_singular.cpp: its
    # change shrinks with the command step), if steep where the damping sets in: here within
    # 15 command steps (0.72 of 0.057 deg; the switch to point-only jumped by 0.98 deg).
    with open(work / "replay-no-rate-limit.csv") as f:
        rows = list(csv.DictReader(f))
    change = np.abs(np.diff(joints(rows, "corrected_q{}_deg") - joints(rows, "commanded_q{}_deg"), axis=0)).max()
    step = np.abs(np.diff(joints(rows, "commanded_q{}_deg"), axis=0)).max()
    assert np.isclose(fig["no_rate_limit_largest_change_deg"], math.degrees(change), rtol=1e-6)
    assert change < 15 * step
    assert fig["corrected"] == ok.sum()
    for key, e in (("without", without), ("default_ok", with_[ok]), ("default_residual", with_[~ok]),
                   ("default_all", with_), ("no_rate_limit_all", free)):
        assert np.isclose(fig[f"{key}_max_mm"], e.max(), rtol=1e-6, atol=1e-9), key
        assert np.isclose(fig[f"{key}_rms_mm"], rms(e), rtol=1e-6, atol=1e-9), key
