"""Compensation never makes the tool worse (design §12; docs/guide/daemon.md, "The objective"),
on random chains of every solver shape, not only the bundled machines.

Each shape is a machine file written here (axes, location errors of every axis, offsets as
constants), built by `chaincomp build` and called through its library. Hypothesis draws the
constants (the chain's geometry), the errors (a few µm and arcsec) and the command (anywhere,
0.1-30 degrees from a singular pose, or at a limit). The truth is a numpy model of the same
chain written in this test: the objective |point error|^2 + (100 mm * direction error)^2 (with
a tool frame the rotation angle) of the corrected target must not exceed the command's, the
point error must not grow, a status 0 must mean the whole pose is within 1 nm and 0.001",
and where the shape's axes can hold the whole pose away from singular poses they must."""

import math
import os
import subprocess

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from helpers import PY, ROOT
from test_build_solver import Loaded
from chain_shapes import (ARCSEC, ARM3, BY_NAME, DEG, SHAPES, errors_of, far_from_singular, internal, objective,
                          pose_error, score)


@pytest.fixture(scope="module")
def libraries(tmp_path_factory):
    """The shapes' libraries by name, each built when first asked for (the tests selected build
    only their own): ``libraries[name]``."""
    folder = tmp_path_factory.mktemp("shapes")
    env = dict(os.environ, XDG_CACHE_HOME=str(tmp_path_factory.mktemp("cache")))

    class Built(dict):
        def __missing__(self, name):
            shape = ARM3 if name == ARM3.name else BY_NAME[name]
            path = folder / f"{name}.yaml"
            path.write_text(shape.yaml())
            proc = subprocess.run([PY, "-m", "chaincomp.cli.main", "build", str(path)], cwd=ROOT, env=env,
                                  capture_output=True, text=True, timeout=900)
            assert proc.returncode == 0, proc.stderr
            self[name] = proc.stdout.strip()
            return self[name]
    return Built()


unit = st.floats(0, 1, allow_nan=False)


@pytest.mark.slow  # nine models built (about three minutes on two cores)
@pytest.mark.parametrize("name", [s.name for s in SHAPES])
@settings(max_examples=60, derandomize=True, deadline=None, suppress_health_check=list(HealthCheck))
@given(kind=st.sampled_from(["anywhere", "near_singular", "at_limit"]), draws=st.lists(unit, min_size=70, max_size=70),
       signs=st.lists(st.floats(-1, 1, allow_nan=False), min_size=60, max_size=60))
def test_compensation_is_never_worse(libraries, name, kind, draws, signs):
    shape = BY_NAME[name]
    lib = _loaded(libraries, name)
    status, corrected, residual, before, after, geometry, errors, q, nominal = score(shape, lib, draws, signs, kind)
    names = [a[0] for a in shape.axes]
    # the test's model is the library's (both ways), else nothing below means anything
    assert np.allclose(np.concatenate(nominal)[:lib.pose_size], lib.pose(lib.entry.pose_nominal, q), atol=1e-9)
    actual_after = shape.pose({**geometry, **errors, **dict(zip(names, corrected))})
    assert np.allclose(np.concatenate(actual_after)[:lib.pose_size], lib.pose(lib.entry.pose_exact, corrected),
                       atol=1e-9)
    assert status in (0, 1), status
    assert objective(*after) <= objective(*before) * (1 + 1e-9) + 1e-18, (before, after)
    assert after[0] <= before[0] + 1e-9, (before, after)
    # the residual reported is the pose's, the direction included where the shape cannot correct it
    assert residual[0] == pytest.approx(after[0], abs=1e-9)
    assert residual[1] == pytest.approx(after[1], abs=1e-9)
    if status == 0:
        assert after[0] <= 1e-6 and after[1] <= 0.001 * ARCSEC, after
    # slides reach any point: the point is corrected in full, except within 1 deg of a singular
    # pose (a nutating table at B = 180 deg left 0.27 of 5.8 um: the damped rotary steps stop
    # before the slides' last step; never worse, but not the whole point)
    at_singular = any(abs(math.sin(q[names.index(axis)] - value * DEG)) < math.sin(1 * DEG)
                      for axis, value in shape.singular.items())
    if {"X", "Y", "Z"} <= set(names) and not at_singular:
        assert after[0] <= 1e-6, after
    rotary_axes = [a[0] for a in shape.axes if a[1] == "deg"]
    if len(rotary_axes) == 1:
        # one rotary axis: the direction it leaves is the least it can (the slides then hold the
        # point), found here by a parabola through the direction error squared around the answer
        i = names.index(rotary_axes[0])

        def tilt2(angle):
            moved = dict(zip(names, corrected), **{names[i]: angle})
            return pose_error(shape, shape.pose({**geometry, **errors, **moved}), nominal)[1] ** 2
        h = 1e-3
        f0, fm, fp = tilt2(corrected[i]), tilt2(corrected[i] - h), tilt2(corrected[i] + h)
        curvature = (fp - 2 * f0 + fm) / (2 * h * h)
        least = f0 - (fp - fm) ** 2 / (16 * h * h * curvature) if curvature > 0 else 0.0
        assert after[1] ** 2 <= least + 1e-20, (after, math.sqrt(max(least, 0)))
    if shape.corrects_all and kind != "near_singular" and far_from_singular(shape, q):
        assert status == 0 and after[0] <= 1e-6 and after[1] <= 0.001 * ARCSEC, (q, after)


_LOADED = {}


def _loaded(libraries, name):
    if name not in _LOADED:
        _LOADED[name] = Loaded(libraries[name], values={})
    return _LOADED[name]


def _weighted_optimum(shape, values, q, nominal, weight):
    """The axes minimising |point error|^2 + (weight * direction error)^2 near q: Gauss-Newton
    on the numpy model with a central-difference Jacobian (the test's own solver)."""
    names = [a[0] for a in shape.axes]

    def residual(x):
        p, z, _ = shape.pose({**values, **dict(zip(names, x))})
        return np.concatenate([p - nominal[0], weight * (z - nominal[1])])
    x = np.array(q, dtype=float)
    for _ in range(20):
        J = np.column_stack([(residual(x + h) - residual(x - h)) / 2e-7 for h in np.eye(len(x)) * 1e-7])
        step = np.linalg.lstsq(J, -residual(x), rcond=None)[0]
        x = x + step
        if np.abs(step).max() < 1e-14:
            break
    return x


@pytest.mark.slow  # one model built (about 30 s)
@pytest.mark.parametrize("case", range(4))
def test_the_direction_weight_decides_the_compromise(libraries, case):
    """Three joints for point and direction (five conditions): the published correction is the
    optimum of the objective at the weight passed, found again here by the numpy model, and a
    weight of 1 mm and one of 1000 mm publish different corrections, each the better by its own
    objective. `before` is the command's own error, by the numpy model too."""
    shape = ARM3
    lib = Loaded(libraries[shape.name], values={})
    rng = np.random.default_rng(40 + case)
    geometry = {c: internal(shape, u, nominal) for c, (u, nominal, _, _) in shape.constants.items()}
    errors = errors_of(shape, rng.uniform(-1, 1, 40))
    lib.prepare({**geometry, **errors})
    # away from the straight arm (q3 = 0) and from the shoulder over the base
    q = np.radians([rng.uniform(-180, 180), rng.uniform(20, 70), rng.uniform(30, 120)])
    names = [a[0] for a in shape.axes]
    nominal = shape.pose({**geometry, **{e: 0.0 for e in errors}, **dict(zip(names, q))})
    before_numpy = pose_error(shape, shape.pose({**geometry, **errors, **dict(zip(names, q))}), nominal)
    results = {}
    for weight in (1.0, 1000.0):
        lib.prepare({**geometry, **errors})  # a fresh workspace: no warm start from the other weight
        residual, before = np.zeros(2), np.zeros(2)
        status, corrected = lib.compensate(q, residual, weight=weight, before=before)
        assert status == 1  # three joints cannot hold both
        assert before == pytest.approx(before_numpy, abs=1e-12)
        after = pose_error(shape, shape.pose({**geometry, **errors, **dict(zip(names, corrected))}), nominal)
        assert residual == pytest.approx(after, abs=1e-12)
        optimum = _weighted_optimum(shape, {**geometry, **errors}, q, nominal, weight)
        best = pose_error(shape, shape.pose({**geometry, **errors, **dict(zip(names, optimum))}), nominal)
        # (the solver's chord keeps the Jacobian of the command: its fixed point lies off the
        # optimum by about the correction (1e-5 rad) times the residual's share, 3e-10 rad here)
        assert np.abs(corrected - optimum).max() < 1e-8, (weight, corrected - optimum)
        assert objective(*after, weight) <= objective(*best, weight) * (1 + 1e-6) + 1e-18
        assert objective(*after, weight) < objective(*before_numpy, weight)
        results[weight] = corrected, after
    (c1, a1), (c1000, a1000) = results[1.0], results[1000.0]
    assert np.abs(c1 - c1000).max() > 1e-7  # rad: a different correction published
    assert objective(*a1, 1.0) < objective(*a1000, 1.0) and objective(*a1000, 1000.0) < objective(*a1, 1000.0)
    assert a1[0] < a1000[0] and a1000[1] < a1[1]  # the heavier weight turns the tool, the lighter places it
