"""chaincomp testvectors on a machine with a tool frame: pose size 9 (point, direction, the
frame's x axis), as the generated Pose lays it out, so the C++ test_models can read them.

Truth from outside the code: a numpy model of the two-axis head of test_tool_frame, written
here; its order-1 error is the odd part (f(ε) − f(−ε))/2 and its order-2 error f(ε) − f(0),
both to O(ε³).
"""

from __future__ import annotations

import numpy as np

import pytest

from helpers import head_file, run_verb

L = 100.0


def head(A, B, e1, e2, e3, d1):
    def R(axis, a):
        c, s = np.cos(a), np.sin(a)
        i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
        m = np.eye(3)
        m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
        return m
    r = R("z", A) @ R("x", e1) @ R("y", B + e2) @ R("z", e3)
    return np.concatenate([r @ [d1, 0, L + 10], r @ [0, 0, 1], r @ [0, 1, 0]])


@pytest.mark.slow
def test_testvectors_of_a_frame_are_point_direction_and_x_axis(tmp_path):
    out = tmp_path / "head.vectors"
    code, _, err = run_verb("testvectors", head_file(tmp_path), "--count", 5, "--seed", 3, "-o", out)
    assert code == 0, err
    lines = [ln for ln in out.read_text().splitlines() if not ln.startswith("#")]
    count, n_axes, n_params, pose_size = map(int, lines[0].split())
    assert (count, n_axes, n_params, pose_size) == (5, 2, 5, 9)
    for line in lines[1:]:
        v = np.array(line.split(), float)
        assert v.size == n_axes + n_params + 4 * pose_size
        (A, B), (_, e1, e2, e3, d1) = v[:2], v[2:7]      # params in kParams order: L, then the errors
        exact, nominal, order1, order2 = v[7:].reshape(4, pose_size)
        eps = np.array([e1, e2, e3, d1])
        f = lambda s: head(A, B, *(s * eps))     # noqa: E731
        np.testing.assert_allclose(exact, f(1), atol=1e-12)
        np.testing.assert_allclose(nominal, f(0), atol=1e-12)
        np.testing.assert_allclose(order1, (f(1) - f(-1)) / 2, atol=1e-10)
        np.testing.assert_allclose(order2, f(1) - f(0), atol=1e-10)
        assert np.abs(order2 - order1).max() > 1e-9     # the second order is there, and told apart
