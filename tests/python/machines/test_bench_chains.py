"""The long-chain benchmark's machines (tools/bench_machines) against textbook products
written here in numpy from the published tables (UR5 standard DH, Franka Panda modified
DH, a trunnion's nominal chain), and tools/bench_chains' operation counter on hand-counted
C++ lines."""

import importlib.machinery
import importlib.util
import os

import numpy as np
import pytest

from chaincomp import ExactModel, load_machine
from chaincomp.analysis.lint import lint

from arm_models import panda, rx, rz, tr, ur5
from helpers import ROOT

MACHINES = os.path.join(ROOT, "tools", "bench_machines")
RNG = np.random.default_rng(16)


def bench_chains():
    path = os.path.join(ROOT, "tools", "bench_chains")
    loader = importlib.machinery.SourceFileLoader("bench_chains", path)
    module = importlib.util.module_from_spec(importlib.util.spec_from_loader("bench_chains", loader))
    loader.exec_module(module)
    return module


def random_axes(m):
    return {s.name: s.to_internal(RNG.uniform(*s.limits)) for s in m.axes}


def check(m, q, T, tool=(30.0, 0.0, 120.0)):
    point, direction = ExactModel(m).pose(q)
    assert np.allclose(point, (T @ np.array([*tool, 1.0]))[:3], atol=1e-9)
    assert np.allclose(direction, T[:3, 2], atol=1e-12)


@pytest.mark.parametrize("name", ["ur5", "ur5_blocks"])
def test_ur5_is_the_standard_dh_product(name):
    m = load_machine(os.path.join(MACHINES, f"{name}.yaml"))
    assert len(m.errors) == (24 if name == "ur5" else 36)
    assert {s.name for s in m.constants} >= {f"al{i}" for i in range(1, 7)}  # the twists are symbols
    for _ in range(5):
        q = random_axes(m)
        check(m, q, ur5([q[f"q{i + 1}"] for i in range(6)]))


def test_panda_gantry_is_the_modified_dh_product_on_the_gantry():
    m = load_machine(os.path.join(MACHINES, "panda_gantry.yaml"))
    assert len(m.axes) == 9 and len(m.errors) == 41
    for _ in range(5):
        q = random_axes(m)
        gantry = tr(q["X"], 0, 0) @ tr(0, q["Y"], 0) @ tr(0, 0, 50)  # carriage top 50 mm up
        check(m, q, gantry @ panda([q[f"q{i + 1}"] for i in range(7)]))


def test_five_axis_iso_nominal_trunnion_and_its_41_errors():
    m = load_machine(os.path.join(MACHINES, "five_axis_iso.yaml"))
    assert len(m.errors) == 41
    for _ in range(5):
        q = random_axes(m)
        # tool relative to the workpiece: inv(table chain) . head chain; the tables turn by -A, -C
        work = rx(-q["A"]) @ rz(-q["C"]) @ tr(0, 0, 50)
        tool = tr(q["X"], q["Y"], 450 + q["Z"] - 100)
        check(m, q, np.linalg.inv(work) @ tool, tool=(0.0, 0.0, 0.0))


@pytest.mark.parametrize("name", ["ur5", "ur5_blocks", "five_axis_iso", "panda_gantry"])
def test_every_error_moves_the_tool_unless_marked(name):
    assert lint(load_machine(os.path.join(MACHINES, f"{name}.yaml"))) == []


def test_operation_counter_on_hand_counted_lines():
    count = bench_chains().count_ops
    # SymForce's style: (1/2) is a literal, -2 a number, pow one call; 6 = * + * - * pow
    assert count("const Scalar _tmp0 = (Scalar(1) / Scalar(2)) * e(0, 0) + -2*q(0, 0) - "
                 "Scalar(1.5e-3) * std::pow(x, Scalar(2));") == 6
    # chaincomp's style: loads and element stores count nothing; 3 = * + std::sin
    assert count("const double q_q1 = q[0];\nconst double j1 = k0*t.s[1] + std::sin(q_q1);\nG(5, 9) = 0.0;\n"
                 "J(0, 1) = j1;") == 3
    # a comparison is no assignment, a reference to an output no arithmetic; unary minus counts
    assert count("if (J != nullptr) {\n Eigen::Matrix<Scalar, 6, 2>& _J = (*J);\n _J(0, 0) = -_tmp1;") == 1
