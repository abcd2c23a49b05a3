"""Growth through the chain (issue #38): expressions each within their bounds, followed by many
rotations with errors, multiply the expanded pose's terms link by link (236 s and 2.5 GB
measured before the bound). derive counts that growth before expanding anything and refuses at
the element where the count passes EXPANSION_LIMIT: exit 2, FILE:LINE, within 5 s, in little
memory, for derive and for the verbs that derive (generate takes its straight-line code instead).

The truth for the refusal's place: rotations about distinct angles never merge terms (their
sines and cosines are distinct atoms), so the nominal tool point alone holds exactly the terms
of a count recurrence written here (a rotation about x: y, z -> y + z, y + z), a lower bound of
what derive holds; the refusal must come no later than the element where that count passes the
bound. For terms of degree > 0 the same holds with the errors: each rotation's error adds
its own monomial.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time

import pytest

from chaincomp import load_machine
from chaincomp.symbolic.derive import EXPANSION_LIMIT, expansion_peak

from helpers import MACHINES, ROOT, line_holding, write_file

REFUSED_SECONDS = 5             # the bound, interpreter start-up included
REFUSED_RSS = 400 * 2**20       # bytes: the interpreter, sympy and numpy take about 75 MB
ADDRESS_SPACE = 3 * 2**30       # a regression stops here instead of taking the machine's memory
AXES = "xyz"
SUM5 = "X + Y + Z + L + M"      # five distinct symbols


def hostile(n: int, angle: str, translate: str = SUM5) -> str:
    """A modest machine: n rotations (about x, y, z in turn) by ``angle`` (with {i}), then one
    translation, each expression far within the expression bounds."""
    symbols = ["X", "Y", "Z"]
    lines = [f"  - {{name: {s}, role: axis, unit: mm, limits: [-100, 100]}}" for s in symbols]
    lines += ["  - {name: L, role: constant, unit: mm, nominal: 3}", "  - {name: M, role: constant, unit: mm, nominal: 2}"]
    if "A{i}" in angle:
        lines += [f"  - {{name: A{i}, role: axis, unit: deg, limits: [-180, 180]}}" for i in range(n)]
    lines += [f"  - {{name: e{i}, role: error, unit: arcsec}}" for i in range(n)]
    chain = [f"  - {{rotate: {AXES[i % 3]}, angle: {angle.format(i=i)}, label: r{i}}}" for i in range(n)]
    chain.append(f"  - {{translate: [{translate}, {translate}, {translate}]}}")
    return ("name: hostile\nlength_unit: mm\nrotation_sense: right_hand\nsymbols:\n" + "\n".join(lines)
            + "\nchain:\n" + "\n".join(chain) + "\ntool: {point: [0, 0, 0], direction: [0, 0, 1]}\n")


def nominal_crossing(n: int, start: int) -> int | None:
    """The rotation (its index in the chain) after which the nominal tool point of hostile(n,
    'A{i} + e{i}') holds more than EXPANSION_LIMIT terms, or None: the chain applied from the
    tool end, each component starting with ``start`` terms."""
    v = [start] * 3
    plane = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}   # the components a rotation about it mixes
    for i in reversed(range(n)):
        a, b = plane[AXES[i % 3]]
        v[a] = v[b] = v[a] + v[b]
        if sum(v) > EXPANSION_LIMIT:
            return i
    return None


# Runs the command from a small interpreter and reports its peak RSS: a child forked straight from
# pytest (preexec_fn forces a fork) carries pytest's own resident size into its ru_maxrss (Linux
# folds the forked copy's high-water mark in at exec): 500 MB late in a full run, whatever it did.
_MEASURE = """
import os, resource, subprocess, sys
limit, rss_file = int(sys.argv[1]), sys.argv[2]
resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
proc = subprocess.Popen(sys.argv[3:])
_, status, usage = os.wait4(proc.pid, 0)
with open(rss_file, "w") as f:
    f.write(str(usage.ru_maxrss * 1024))
code = os.waitstatus_to_exitcode(status)
sys.exit(code if code >= 0 else 128 - code)
"""


def run_limited(tmp_path, *args):
    """chaincomp ARGS in a process of its own, its address space limited: (result, seconds, its
    peak RSS in bytes, from wait4 in a small parent)."""
    start = time.monotonic()
    rss = tmp_path / "rss"
    with open(tmp_path / "stdout", "w+") as out, open(tmp_path / "stderr", "w+") as err:
        proc = subprocess.Popen([sys.executable, "-c", _MEASURE, str(ADDRESS_SPACE), str(rss),
                                 sys.executable, "-m", "chaincomp.cli.main", *map(str, args)], cwd=ROOT,
                                stdout=out, stderr=err, start_new_session=True)
        timer = threading.Timer(120, lambda: os.killpg(proc.pid, signal.SIGKILL))
        timer.start()
        code = proc.wait()
        timer.cancel()
        seconds = time.monotonic() - start
        out.seek(0)
        err.seek(0)
        result = subprocess.CompletedProcess(args, code, out.read(), err.read())
    return result, seconds, int(rss.read_text()) if rss.exists() else 0


# (id, rotations, their angle, the translation, the order)
SHAPES = [
    ("distinct-angles", 24, "A{i} + e{i}", SUM5, 1),
    ("distinct-angles-order2", 14, "A{i} + e{i}", SUM5, 2),
    ("angle-with-a-sum", 18, "A{i} + e{i}*(1 + X/100)", "X*Y + Z*L + M", 2),
    ("long-chain", 60, "A{i} + e{i}", "X + Y + Z + L*M", 1),
    ("errors-only-order4", 60, "e{i}", SUM5, 4),   # no new atoms: the growth is the errors' monomials
]


@pytest.mark.slow
@pytest.mark.parametrize("shape", SHAPES, ids=[s[0] for s in SHAPES])
def test_growth_through_the_chain_refused_at_its_element(tmp_path, shape):
    _, n, angle, translate, order = shape
    text = hostile(n, angle, translate)
    path = write_file(tmp_path, "m.yaml", text)
    proc, seconds, rss = run_limited(tmp_path, "derive", path, "--order", order)
    assert proc.returncode == 2, (proc.returncode, proc.stderr[-2000:])
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    assert lines[0].startswith(f"chaincomp derive: error: {path}:"), lines[0]
    line = int(lines[0].split(f"{path}:")[1].split(":")[0])
    assert f"at most {EXPANSION_LIMIT:g}" in lines[0], lines[0]
    assert f"{path}:{line}: chain: " in lines[0], lines[0]
    # the element named is one of the rotations, no later (from the tool end) than where the
    # nominal point alone passes the bound
    rotation = int(text.splitlines()[line - 1].split("label: r")[1].rstrip("}"))
    crossing = nominal_crossing(n, len(translate.split("+"))) if "A{i}" in angle else None
    if crossing is not None:
        assert rotation >= crossing, (rotation, crossing)
    assert seconds < REFUSED_SECONDS, seconds
    assert rss < REFUSED_RSS, rss


def test_the_nominal_count_is_a_lower_bound_of_the_true_expansion(tmp_path):
    """The recurrence above against sympy's expansion of a short chain of the same shape: the
    nominal point's terms, counted by sympy, are the recurrence's."""
    import sympy as sp
    from chaincomp.symbolic.derive import derive
    n = 5
    m = load_machine(write_file(tmp_path, "m.yaml", hostile(n, "A{i} + e{i}")))
    d = derive(m, 1)
    counts = [len(sp.Add.make_args(sp.expand(d.nominal(s)))) for s in d.point]
    v = [5] * 3
    plane = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}
    for i in reversed(range(n)):
        a, b = plane[AXES[i % 3]]
        v[a] = v[b] = v[a] + v[b]
    assert counts == v


@pytest.mark.slow
def test_generate_takes_straight_line_code_instead(tmp_path):
    """generate does not need the expansion (long chains get straight-line code): the same
    machine is generated, quickly."""
    path = write_file(tmp_path, "m.yaml", hostile(24, "A{i} + e{i}"))
    out = tmp_path / "gen"
    proc, seconds, rss = run_limited(tmp_path, "generate", path, "-o", out)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert (out / "hostile.cpp").exists()
    assert seconds < 4 * REFUSED_SECONDS and rss < REFUSED_RSS, (seconds, rss)


# The calibration: the largest count of the bundled machines and the arms of example-robot-data
# (measured on the expanded series: docs/reference/errors.md) stays below the bound with room.
CALIBRATION = [(os.path.join(MACHINES, f), k) for f in sorted(os.listdir(MACHINES)) if f.endswith(".yaml")
               for k in (1, 2)]
CALIBRATION += [(os.path.join(MACHINES, "panda.yaml"), 3), (os.path.join(MACHINES, "panda.yaml"), 4)]
CALIBRATION += [(os.path.join(ROOT, "tools", "bench_machines", f), k)
                for f in sorted(os.listdir(os.path.join(ROOT, "tools", "bench_machines"))) for k in (1, 2)]


@pytest.mark.parametrize("path,order", CALIBRATION,
                         ids=[f"{os.path.basename(p)}-{k}" for p, k in CALIBRATION])
def test_bundled_machines_stay_within_the_bound_with_room(path, order):
    assert expansion_peak(load_machine(path), order) * 1.4 < EXPANSION_LIMIT


ROBOTS = os.path.join(ROOT, ".venv", "lib", "python3.11", "site-packages", "cmeel.prefix", "share",
                      "example-robot-data", "robots")
# example-robot-data's arms (URDF, base link, tip link), imported with every error import-urdf
# declares; xarm7 and so100 are the largest at order 2
ARMS = [("ur_description/urdf/ur5_robot.urdf", "base_link", "ee_link"),
        ("ur_description/urdf/ur10_robot.urdf", "base_link", "ee_link"),
        ("panda_description/urdf/panda.urdf", "panda_link0", "panda_hand_tcp"),
        ("xarm_description/urdf/xarm7.urdf", "link_base", "link7"),
        ("z1_description/urdf/z1.urdf", "link00", "link06"),
        ("so_arm_description/urdf/so100.urdf", "base", "jaw"),
        ("kinova_description/robots/kinova.urdf", "j2s6s200_link_base", "j2s6s200_end_effector"),
        ("talos_data/robots/talos_left_arm.urdf", "arm_left_1_link", "gripper_left_base_link")]


@pytest.mark.skipif(not os.path.isdir(ROBOTS), reason="example-robot-data not installed")
@pytest.mark.parametrize("urdf,base,tip", ARMS, ids=[a[0].split("/")[-1] for a in ARMS])
def test_example_robot_data_arms_stay_within_the_bound_with_room(tmp_path, urdf, base, tip):
    from helpers import cli
    out = tmp_path / "arm.yaml"
    cli("import-urdf", os.path.join(ROBOTS, urdf), "--base", base, "--tip", tip, "--errors", "all",
        "--tool-point", "30,-20,120", "-o", out)
    assert expansion_peak(load_machine(str(out)), 2) * 1.4 < EXPANSION_LIMIT
