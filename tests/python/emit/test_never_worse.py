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
from chain_shapes import ARCSEC, BY_NAME, SHAPES, far_from_singular, objective, pose_error, score


@pytest.fixture(scope="module")
def libraries(tmp_path_factory):
    """Every shape built into a library (two compiles at a time)."""
    folder = tmp_path_factory.mktemp("shapes")
    env = dict(os.environ, XDG_CACHE_HOME=str(tmp_path_factory.mktemp("cache")))
    paths = {}
    for shape in SHAPES:
        path = folder / f"{shape.name}.yaml"
        path.write_text(shape.yaml())
        paths[shape.name] = str(path)
    built, pending = {}, list(SHAPES)
    while pending:
        batch, pending = pending[:2], pending[2:]
        procs = {s.name: subprocess.Popen([PY, "-m", "chaincomp.cli.main", "build", paths[s.name]], cwd=ROOT,
                                          env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                 for s in batch}
        for name, p in procs.items():
            out, err = p.communicate(timeout=900)
            assert p.returncode == 0, err
            built[name] = out.strip()
    return built


unit = st.floats(0, 1, allow_nan=False)


@pytest.mark.slow  # eight models built (about two minutes on two cores)
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
    if {"X", "Y", "Z"} <= set(names):  # slides reach any point: the point is corrected in full
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
