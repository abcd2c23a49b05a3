"""What the tests share: the repository's paths, the bundled machines, the command line run in a
process or in this one, and the checks every bad-input test makes (exit 2, the message, no
traceback). Imported as `helpers` (tests/python is on sys.path: conftest.py puts it there)."""

import contextlib
import functools
import io
import json
import math
import os
import subprocess
import sys

import pytest

from arm_models import panda_frame, ur5_frame

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))  # the repository
MACHINES = os.path.join(ROOT, "configs", "machines")
PARAMS = os.path.join(ROOT, "configs", "params")
DAEMON = os.path.join(ROOT, "build", "bin", "chaincompd")
PY = os.path.join(ROOT, ".venv", "bin", "python")
# LCM tests across processes run inside a network namespace this script makes
NETNS = os.path.join(ROOT, "tests", "e2e", "netns.sh")
# every machine shipped in configs/machines/, so a new one joins every fixture-based test
BUNDLED = sorted(os.path.splitext(f)[0] for f in os.listdir(MACHINES) if f.endswith(".yaml"))


def machine_path(name: str) -> str:
    return os.path.join(MACHINES, name + ".yaml")


def derived(path: str, order: int):
    """derive(machine, order) of a machine file, once a session: an arm's order 2 takes minutes,
    and test_gain, test_jets and test_truncation all compare against the same derivations.
    Shared: only read it, never change it."""
    return _derived(os.path.abspath(path), order)


def truncated(path: str, order: int):
    """TruncatedModel of derived(path, order), once a session (it keeps its lambdified formulas)."""
    return _truncated(os.path.abspath(path), order)


@functools.cache
def _derived(path: str, order: int):
    from chaincomp import derive, load_machine
    return derive(load_machine(path), order)


@functools.cache
def _truncated(path: str, order: int):
    from chaincomp import TruncatedModel
    return TruncatedModel(_derived(path, order))


def run_cli(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    proc = subprocess.run([sys.executable, "-m", "chaincomp.cli.main", *args], capture_output=True,
                          text=True, cwd=ROOT)
    if check and proc.returncode != 0:
        raise AssertionError(f"chaincomp {' '.join(args)} exited {proc.returncode}:\n{proc.stderr}")
    return proc


def cli(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    """run_cli's result from chaincomp's entry point (cli.main.main) in this process: the same
    verb, options, output and exit code, without an interpreter's start-up (about 1 s of CPU a
    call). Keep run_cli, a real process, for at least one test of each verb: the exit path."""
    from chaincomp.cli.main import main
    out, err, here = io.StringIO(), io.StringIO(), os.getcwd()
    os.chdir(ROOT)   # as run_cli's cwd
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main([str(a) for a in args])
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else 1
    finally:
        os.chdir(here)
    proc = subprocess.CompletedProcess(["chaincomp", *args], code, out.getvalue(), err.getvalue())
    if check and code != 0:
        raise AssertionError(f"chaincomp {' '.join(map(str, args))} exited {code}:\n{proc.stderr}")
    return proc


def eval_json(*args: str) -> dict:
    return json.loads(run_cli("eval", *args, "--json").stdout)


def _netns_available() -> bool:
    try:
        return subprocess.run(["unshare", "-rn", "true"], capture_output=True).returncode == 0
    except FileNotFoundError:
        return False


# LCM tests across processes run inside a network namespace they make (tests/e2e/netns.sh)
needs_netns = pytest.mark.skipif(not _netns_available(),
                                 reason="unprivileged network namespaces (unshare -rn) are not permitted here")


def line_of(text: str, at: str) -> int:
    """1-based line where the unique snippet ``at`` starts."""
    assert text.count(at) == 1, f"line marker not unique: {at!r}"
    return text[:text.index(at)].count("\n") + 1


def run_main(capsys, *argv) -> tuple[int, str, str]:
    """chaincomp ARGV through cli.main.main in this process: (exit code, stdout, stderr)."""
    from chaincomp.cli.main import main
    capsys.readouterr()
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def refused(capsys, *argv, match: str) -> str:
    """chaincomp ARGV is refused as bad input: exit 2, ``match`` in the message, no traceback."""
    code, out, err = run_main(capsys, *argv)
    assert code == 2, err
    assert match in err, err
    assert "Traceback" not in err and "internal error" not in err
    return err


def refused_one_line(*argv, match: str) -> str:
    """As refused, through cli() (no capsys), and the message is one line."""
    proc = cli(*argv, check=False)
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert match in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr and "internal error" not in proc.stderr
    assert proc.stderr.count("\n") == 1, proc.stderr   # one line
    return proc.stderr


VMC = machine_path("vmc_xyz")
# the bundled ISO 230-2 runs of five_axis_ac's X axis
RUNS = os.path.join(ROOT, "configs", "measurements", "five_axis_ac-X-positioning.csv")


# ----------------------------------------------------------------------------- files a user writes

# A four-axis machine written the way a user would: X, Y, Z slides and a B table, one error block
# after each, a tool length L.
M4 = """\
name: m4
description: four axis
length_unit: mm
error_block_order: txyz
rotation_sense: right_hand
symbols:
  - {name: X, role: axis, unit: mm, limits: [-300, 300]}
  - {name: Y, role: axis, unit: mm, limits: [-200, 200]}
  - {name: Z, role: axis, unit: mm, limits: [-300, 0]}
  - {name: B, role: axis, unit: deg, limits: [-90, 90]}
  - {name: L, role: constant, unit: mm, nominal: 120}
  - {name: EXX, role: error, unit: um}
  - {name: EYY, role: error, unit: um}
  - {name: EZZ, role: error, unit: um}
  - {name: EAX, role: error, unit: arcsec}
  - {name: EBB, role: error, unit: arcsec}
  - {name: EXB, role: error, unit: um}
chain:
  - {translate: [X, 0, 0]}
  - {errors: {dx: EXX, ex: EAX}}
  - {translate: [0, Y, 0]}
  - {errors: {dy: EYY}}
  - {translate: [0, 0, Z]}
  - {errors: {dz: EZZ}}
  - {rotate: y, angle: B}
  - {errors: {dx: EXB, ey: EBB}}
  - {translate: [0, 0, -L]}
tool:
  point: [0, 0, 0]
  direction: [0, 0, 1]
"""


# A three-joint arm in standard DH with a Hayati beta.
DH = """\
name: dharm
length_unit: mm
symbols:
  - {name: q1, role: axis, unit: deg, limits: [-180, 180]}
  - {name: q2, role: axis, unit: deg, limits: [-180, 180]}
  - {name: q3, role: axis, unit: deg, limits: [-180, 180]}
chain:
  - {dh: {theta: q1, d: 300, a: 0, alpha: pi/2}, errors: auto}
  - {dh: {theta: q2, d: 0, a: 400, alpha: 0}, errors: auto}
  - {beta: 0, errors: auto}
  - {dh: {theta: q3, d: 0, a: 300, alpha: 0}, errors: {theta: auto, a: auto}}
tool:
  point: [50, 20, 0]
"""


URDF = """\
<?xml version="1.0"?>
<robot name="r1">
  <link name="base"/>
  <link name="l1"/>
  <link name="l2"/>
  <link name="tip"/>
  <joint name="j1" type="revolute">
    <parent link="base"/><child link="l1"/>
    <origin xyz="0.01 0.002 0.3" rpy="0.1 -0.2 0.3"/>
    <axis xyz="0 0 1"/>
    <limit lower="-3.1" upper="3.1" effort="1" velocity="1"/>
  </joint>
  <joint name="j2" type="prismatic">
    <parent link="l1"/><child link="l2"/>
    <origin xyz="0.1 0 0"/>
    <axis xyz="1 1 0"/>
    <limit lower="-0.2" upper="0.5" effort="1" velocity="1"/>
  </joint>
  <joint name="f" type="fixed">
    <parent link="l2"/><child link="tip"/>
    <origin xyz="0 0.05 0.05"/>
  </joint>
</robot>
"""


def write_file(tmp_path, name: str, text: str) -> str:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return str(path)


def edited(text: str, old: str, new: str) -> str:
    assert text.count(old) == 1, old
    return text.replace(old, new)


def line_holding(text: str, part: str) -> int:
    """1-based line of the first line of ``text`` holding ``part``."""
    return next(i for i, t in enumerate(text.splitlines(), 1) if part in t)


# m4 with a tool length that needs X above -400 mm (sqrt): finite within X's limits, as the loader
# checks, but not at a set-up written beyond them
M4_SQRT = edited(M4, "{translate: [0, 0, -L]}", "{translate: [0, 0, -L + sqrt(X + 400)]}")


def m4_nominal_rows() -> list[list[str]]:
    """Set-ups of m4 and their nominal tool points (by hand: x = X - L sin B, z = Z - L cos B)."""
    rows = []
    for x, b in ((-300, -90), (0, 0), (300, 90), (100, 30), (-50, -45)):
        rb = math.radians(b)
        rows.append([f"{x}", "10", "-100", f"{b}", f"{x - 120 * math.sin(rb)!r}", "10",
                     f"{-100 - 120 * math.cos(rb)!r}"])
    return rows


def arm_file(tmp_path, name, symbols, chain):
    """A two-joint arm (q1, q2) with the given symbols and chain, written into tmp_path."""
    axes = "".join(f"  - {{name: q{i}, role: axis, unit: deg, limits: [-360, 360]}}\n" for i in (1, 2))
    p = tmp_path / f"{name}.yaml"
    p.write_text(f"name: {name}\nsymbols:\n{axes}{symbols}chain:\n{chain}"
                 "tool:\n  point: [0, 0, 0]\n  direction: [0, 0, 1]\n", encoding="utf-8")
    return p


def ur5_frame_file(tmp_path, tool="  point: [40, 0, 100]\n  direction: [0, 0, 1]\n  reference: [1, 1, 0.3]\n"):
    """configs/machines/ur5.yaml with the tool given a frame (name kept: its params load)."""
    with open(machine_path("ur5")) as f:
        text = f.read()
    head, _ = text.split("\ntool:\n")
    path = tmp_path / "ur5_frame.yaml"
    path.write_text(head + "\ntool:\n" + tool)
    return path


def no_frame_file(tmp_path, name):
    """A bundled arm's file with its tool frame taken out (point and direction kept): the
    machine without a frame that the tests compare against."""
    with open(machine_path(name)) as f:
        head, tool = f.read().split("\ntool:\n")
    kept = [line for line in tool.splitlines(keepends=True) if not line.startswith("  reference:")]
    assert len(kept) == len(tool.splitlines()) - 1, tool    # the bundled file has one reference line
    path = tmp_path / f"{name}_no_frame.yaml"
    path.write_text(head + "\ntool:\n" + "".join(kept))
    return path


def head_file(tmp_path):
    """A two-axis head with three tilt errors, one about the tool axis (seen only by the frame)."""
    path = tmp_path / "head.yaml"
    path.write_text("""name: head
length_unit: mm
rotation_sense: right_hand
symbols:
  - {name: A, role: axis, unit: deg, limits: [-180, 180]}
  - {name: B, role: axis, unit: deg, limits: [-120, 120]}
  - {name: L, role: constant, unit: mm, nominal: 100}
  - {name: e1, role: error, unit: arcsec}
  - {name: e2, role: error, unit: arcsec}
  - {name: e3, role: error, unit: arcsec}
  - {name: d1, role: error, unit: um}
chain:
  - {rotate: z, angle: A}
  - {rotate: x, angle: e1}
  - {rotate: y, angle: B + e2}
  - {rotate: z, angle: e3}
  - {translate: [d1, 0, L]}
tool: {point: [0, 0, 10], direction: [0, 0, 1], reference: [0, 1, 0]}
""")
    return path


def panda_frame_file(tmp_path):
    with open(machine_path("panda")) as f:
        head, _ = f.read().split("\ntool:\n")
    path = tmp_path / "panda_frame.yaml"
    path.write_text(head + "\ntool:\n  point: [40, 0, 103.4]\n  direction: [0, 1, 0]\n  reference: [0, 0, 1]\n")
    return path


# a bundled arm with a tool frame: its file and its numpy model (arm_models)
FRAME_ARMS = {"ur5": (ur5_frame_file, ur5_frame), "panda": (panda_frame_file, panda_frame)}


# ----------------------------------------------------------------------------- processes

def run_verb(*args, cwd=None):
    """chaincomp ARGS in a process: (exit code, stdout, stderr)."""
    proc = subprocess.run([sys.executable, "-m", "chaincomp.cli.main", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd or ROOT, timeout=900)
    return proc.returncode, proc.stdout, proc.stderr


# ----------------------------------------------------------------------------- bad input

def run_in_process(*args):
    """In this process (cli.main.main), without a process's ~1 s of start-up."""
    return cli(*args, check=False)


def one_error_line(res, verb, *words):
    assert res.returncode == 2, (res.returncode, res.stdout[-500:], res.stderr[-2000:])
    assert "Traceback" not in res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"chaincomp {verb}: error: "), res.stderr
    for w in words:
        assert w in lines[0], (w, lines[0])
    return lines[0]


def derive_text(tmp_path, text):
    path = tmp_path / "m.yaml"
    path.write_text(text)
    return subprocess.run([sys.executable, "-m", "chaincomp.cli.main", "derive", str(path)], capture_output=True,
                          text=True, cwd=ROOT, timeout=120)


def refused_field(proc, field, word):
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert f" {field}: " in proc.stderr and word in proc.stderr, proc.stderr
