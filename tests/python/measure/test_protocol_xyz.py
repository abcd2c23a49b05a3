"""``chaincomp protocol`` on machines without rotary axes: laser runs, ISO 230-6 diagonals and
tracker points, and what each identifies.

The truth is this file's own: the chain multiplied here as 4x4 matrices, the gains of every
reading taken by central differences of that product (tool point and tool rotation), the
readings stacked with their unknown zeros as the module docstring of protocol_linear and the
docs/guide/calibration.md ("Machines without rotary axes") define them, and the rank and the
identified parameters found by numpy's SVD. Physical
facts are checked from the machine's constants and ISO 230-1 / 230-6: the positioning run of
X on vmc_xyz sees pitch with the lever H + Z - L, squareness needs the diagonals, a tool length
error only the tracker.
"""

import functools
import json

import numpy as np
import pytest
import sympy as sp

from chaincomp import load_machine
from chaincomp.model.machine import ROT_PLANE, Rotation

from helpers import cli, machine_path, run_cli

GANTRY = """\
name: gantry_xyz
description: test gantry, three tool-side slides with their ISO 230-1 errors, squareness and a tool length error
length_unit: mm
rotation_sense: right_hand
error_block_order: txyz
symbols:
  - {name: X, role: axis, unit: mm, limits: [0, 1000], meaning: X}
  - {name: Y, role: axis, unit: mm, limits: [-300, 300], meaning: Y}
  - {name: Z, role: axis, unit: mm, limits: [-400, 0], meaning: Z}
  - {name: L, role: constant, unit: mm, nominal: 150, meaning: tool length}
""" + "".join(f"  - {{name: E{c}{a}, role: error, unit: {'um' if c in 'XYZ' else 'arcsec'}, meaning: {c} of {a}}}\n"
              for a in "XYZ" for c in "XYZABC") + """\
  - {name: EC0Y, role: error, unit: arcsec, meaning: squareness Y to X}
  - {name: EB0Z, role: error, unit: arcsec, meaning: squareness Z to X}
  - {name: EA0Z, role: error, unit: arcsec, meaning: squareness Z to Y}
  - {name: Tz, role: error, unit: um, meaning: tool length error}
chain:
  - {translate: [X, 0, 0]}
  - {errors: {dx: EXX, dy: EYX, dz: EZX, ex: EAX, ey: EBX, ez: ECX}}
  - {translate: [-Y*sin(EC0Y), Y*cos(EC0Y), 0]}
  - {errors: {dx: EXY, dy: EYY, dz: EZY, ex: EAY, ey: EBY, ez: ECY}}
  - {translate: [Z*sin(EB0Z), -Z*sin(EA0Z), Z]}
  - {errors: {dx: EXZ, dy: EYZ, dz: EZZ, ex: EAZ, ey: EBZ, ez: ECZ}}
  - {translate: [0, 0, -L - Tz]}
tool:
  point: [0, 0, 0]
  direction: [0, 0, 1]
"""

H = 1e-5          # central-difference step, internal units (mm, rad)


@pytest.fixture(scope="module")
def gantry(tmp_path_factory):
    path = tmp_path_factory.mktemp("xyz") / "gantry_xyz.yaml"
    path.write_text(GANTRY)
    return str(path)


def protocol_json(path, *args):
    return json.loads(run_cli("protocol", path, *args, "--format", "json").stdout)


class Chain:
    """The tool pose as this test multiplies it: 4x4 matrices, leftmost first."""

    def __init__(self, m):
        self.m = m
        syms = [s.sym for s in m.symbols]
        self.steps = []
        for el in m.chain:
            if isinstance(el, Rotation):
                self.steps.append(("r", el.axis, sp.lambdify(syms, el.angle)))
            else:
                self.steps.append(("t", None, [sp.lambdify(syms, v) for v in el.vector]))
        self.point = [sp.lambdify(syms, v) for v in m.tool_point]

    def pose(self, values):
        args = [values[s.name] for s in self.m.symbols]
        t = np.eye(4)
        for kind, axis, f in self.steps:
            step = np.eye(4)
            if kind == "r":
                a = float(f(*args))
                i, j = ROT_PLANE[axis]
                step[i, i], step[i, j], step[j, i], step[j, j] = np.cos(a), -np.sin(a), np.sin(a), np.cos(a)
            else:
                step[:3, 3] = [float(g(*args)) for g in f]
            t = t @ step
        return t[:3, :3], (t @ np.array([*(float(g(*args)) for g in self.point), 1.0]))[:3]

    def gains(self, axes):
        """(point (3, errors), rotation (3, errors)) at one pose: central differences."""
        m = self.m
        base = m.nominal_values()
        base.update(axes)
        r0, _ = self.pose(base)
        point, rot = [], []
        for e in m.errors:
            (rp, pp), (rm, pm) = (self.pose({**base, e.name: s * H}) for s in (1, -1))
            point.append((pp - pm) / (2 * H))
            w = (rp - rm) / (2 * H) @ r0.T
            rot.append([w[2, 1], w[0, 2], w[1, 0]])
        return np.array(point).T, np.array(rot).T


def reading_rows(m, chain, reading, params, measured=None):
    """Rows of one reading in the parameters, and its unknown zero's columns."""
    names = [s.name for s in m.errors]
    rows, axis_at = [], []
    for setup in reading["setups"]:
        axes = {k: m.symbol(k).to_internal(v) for k, v in setup.items()}
        point, rot = chain.gains(axes)
        if reading["vector"] is None:
            gs = [point[i] for i in range(3) if "xyz"[i] in measured]
        else:
            gs = [np.array(reading["vector"]) @ (point if reading["channel"] == "point" else rot)]
        for g in gs:
            row = []
            for p in params:
                ge = g[names.index(p["error"])]
                if p["axis"] is None:
                    row.append(ge)
                    continue
                s = m.symbol(p["axis"])
                lo, hi = (s.to_internal(v) for v in s.limits)
                t = (axes[p["axis"]] - s.to_internal(s.default_position)) / (0.5 * (hi - lo))
                row.append(ge * t ** {"offset": 0, "slope": 1, "shape": 2}[p["part"]])
            rows.append(row)
            axis_at.append(axes.get(reading.get("axis")) if reading.get("axis") else 0.0)
    rows = np.array(rows)
    zero = reading["unknown_zero"]
    if zero == "none":
        return rows, np.zeros((len(rows), 0))
    cols = [np.ones(len(rows))]
    if zero == "offset and slope":
        cols.append(np.array(axis_at))
    return rows, np.stack(cols, axis=1)


def own_rank(blocks, n):
    """Rank of the stacked readings (unknown zeros block-diagonal), columns scaled to unit norm,
    and the parameters (first n columns) outside the null space."""
    width = sum(z.shape[1] for _, z in blocks)
    full, at = [], 0
    for rows, zero in blocks:
        extra = np.zeros((len(rows), width))
        extra[:, at:at + zero.shape[1]] = zero
        at += zero.shape[1]
        full.append(np.hstack([rows, extra]))
    a = np.vstack(full)
    norm = np.linalg.norm(a, axis=0)
    keep = norm > 1e-9 * norm.max()
    s = np.linalg.svd(a[:, keep] / norm[keep], compute_uv=False)
    rank = int((s > 1e-6 * s[0]).sum())
    # the rank is not a matter of tolerance: nothing between 1e-8 and 1e-5 of the largest
    assert not ((s > 1e-8 * s[0]) & (s < 1e-5 * s[0])).any(), s
    _, _, vt = np.linalg.svd(a[:, keep] / norm[keep])
    null = vt[rank:]
    weight = np.zeros(a.shape[1])
    weight[keep] = (null ** 2).sum(axis=0)
    identified = {i for i in range(n) if keep[i] and weight[i] < 1e-6}
    return rank, identified


@functools.lru_cache(maxsize=None)
def check_against_own_analysis(path):
    m = load_machine(path)
    chain = Chain(m)
    doc = protocol_json(path)
    params = doc["parameters"]
    labels = [p["label"] for p in params]
    stages = {"laser runs": doc["laser_runs"], "diagonals": doc["diagonals"], "tracker": [doc["tracker"]]}
    blocks, cumulative = [], set()
    assert [s["name"] for s in doc["stages"]] == [k for k, v in stages.items() if v]
    for st in doc["stages"]:
        blocks += [reading_rows(m, chain, rd, params, doc["tracker"]["measured"]) for rd in stages[st["name"]]]
        rank, identified = own_rank(blocks, len(params))
        cumulative |= set(st["identified"])
        assert st["rank"] == rank, (st["name"], st["rank"], rank)
        assert cumulative == {labels[i] for i in identified}, (st["name"], cumulative ^ {labels[i] for i in identified})
    assert set(doc["unidentifiable"]) == set(labels) - cumulative
    # each laser run names the errors of its axis it sees, with the gain at mid-travel
    names = [s.name for s in m.errors]
    for run in doc["laser_runs"]:
        mid = run["setups"][len(run["setups"]) // 2]
        point, rot = chain.gains({k: m.symbol(k).to_internal(v) for k, v in mid.items()})
        g = np.array(run["vector"]) @ (point if run["channel"] == "point" else rot)
        for e, coeff in run["measures"].items():
            assert coeff == pytest.approx(g[names.index(e)], rel=1e-6, abs=1e-9), (run["name"], e)
    return m, doc


@pytest.mark.slow
@pytest.mark.parametrize("name", ["vmc_xyz", "me220_xz"])
def test_ranks_match_an_own_analysis_bundled(name):
    check_against_own_analysis(machine_path(name))


@pytest.mark.slow
def test_vmc_xyz_what_each_measurement_identifies():
    m, doc = check_against_own_analysis(machine_path("vmc_xyz"))
    runs = {r["name"]: r for r in doc["laser_runs"]}
    lever = m.symbol("H").nominal - m.symbol("L").nominal    # Z = 0: from X's point the tip is at H + Z - L
    assert runs["X positioning"]["measures"] == pytest.approx({"EXX": 1.0, "EBX": lever})
    assert runs["X angular about y"]["measures"] == pytest.approx({"EBX": 1.0})
    assert runs["Z positioning"]["measures"] == pytest.approx({"EZZ": 1.0})
    assert "EC0Y" in runs["Y straightness in x"]["slope_from"]      # squareness: a slope, removed
    found = {p["label"]: p["identified_by"] for p in doc["parameters"]}
    # ISO 230-6: the diagonals (with the axes' scales from the laser) give the squareness
    for sq in ("EC0Y", "EB0Z", "EA0Z"):
        assert found[sq] == "diagonals"
    for e in ("EXX", "EYY", "EZZ"):
        assert found[f"{e} slope"] == "laser runs" and found[f"{e} shape"] == "laser runs"
    assert "EXX offset" in doc["datum"] and "EYX slope" in doc["datum"] and "EXX slope" not in doc["datum"]
    assert doc["stages"][1]["name"] == "diagonals" and doc["stages"][1]["identified"] == ["EC0Y", "EB0Z", "EA0Z"]


@pytest.mark.slow
def test_gantry_written_here(gantry):
    m, doc = check_against_own_analysis(gantry)
    found = {p["label"]: p["identified_by"] for p in doc["parameters"]}
    assert found["Tz"] == "tracker"                     # a tool length: only an absolute measurement
    assert {found[s] for s in ("EC0Y", "EB0Z", "EA0Z")} == {"diagonals"}
    assert len(doc["diagonals"]) == 4 and len(doc["tracker"]["setups"]) == 27
    text = run_cli("protocol", gantry).stdout
    assert "X positioning" in text and "measures EXX" in text and "2. Diagonals (ISO 230-6" in text
    assert "+ diagonals" in text and "EC0Y" in text


@pytest.mark.slow
def test_measured_coordinates_and_assumed_zero(gantry):
    doc = protocol_json(gantry, "--measure", "x,y", "--assume-zero", "EC0Y")
    assert doc["tracker"]["measured"] == ["x", "y"] and doc["assumed_zero"] == ["EC0Y"]
    labels = {p["label"] for p in doc["parameters"]}
    assert "EC0Y" not in labels and "Tz" in labels
    assert "Tz" in doc["unidentifiable"]          # only z sees the tool length


@pytest.mark.parametrize("args, word", [
    (("--angles", "0,90"), "--angles: vmc_xyz has no rotary axis"),
    (("--prefer", "EXX"), "--prefer: vmc_xyz has no rotary axis"),
    (("--index", "o1"), "--index: only with --poses N"),
    (("-o", "poses.csv"), "-o: only with --poses N"),
    (("--set", "X=500"), "--set X: 500 mm is outside the axis' limits [-400, 400]"),
    (("--set", "H=1"), "--set: 'H' is not an axis"),
    (("--measure", "x,q"), "--measure: unknown coordinate 'q'"),
    (("--assume-zero", "NOPE"), "--assume-zero: unknown error 'NOPE'"),
])
def test_bad_options_exit_2(args, word):
    proc = cli("protocol", machine_path("vmc_xyz"), *args, check=False)   # in this process
    assert proc.returncode == 2 and proc.stdout == "" and "Traceback" not in proc.stderr
    assert word in proc.stderr and len(proc.stderr.strip().splitlines()) == 1, proc.stderr


# ------------------------------------------------------------- simulate-measurements defaults

def setups_of(path):
    rows = [r for r in open(path).read().splitlines() if r and not r.startswith("#")]
    return rows[0].split(","), [tuple(float(c) for c in r.split(",")) for r in rows[1:]]


@pytest.mark.slow
@pytest.mark.parametrize("name, counts", [("vmc_xyz", (3, 3, 3)), ("me220_xz", (3, 3))])
def test_auto_setups_span_the_travel(name, counts, tmp_path):
    """Never one silent set-up at the origin: every axis at both limits and mid-range."""
    m = load_machine(machine_path(name))
    out = tmp_path / "auto.csv"
    proc = run_cli("simulate-measurements", machine_path(name), "-o", str(out))
    header, rows = setups_of(out)
    n = int(np.prod(counts))
    assert len(rows) == n == len(set(r[:len(m.axes)] for r in rows))
    for i, s in enumerate(m.axes):
        lo, hi = s.limits
        assert {r[i] for r in rows} == {lo, 0.5 * (lo + hi), hi}
    assert f"{n} set-ups" in proc.stderr


@pytest.mark.slow
def test_setups_that_cannot_move_are_refused(tmp_path):
    out = tmp_path / "one.csv"
    for spec in ("auto", "random:5"):
        proc = run_cli("simulate-measurements", machine_path("vmc_xyz"), "--setups", spec, "--set", "X=0",
                       "--set", "Y=0", "--set", "Z=-100", "-o", str(out), check=False)
        assert proc.returncode == 2 and "no axis of vmc_xyz is left to move" in proc.stderr, proc.stderr
        assert len(proc.stderr.strip().splitlines()) == 1 and not out.exists()
    # one axis free: three set-ups along it, said on stderr
    proc = run_cli("simulate-measurements", machine_path("vmc_xyz"), "--set", "X=0", "--set", "Y=0", "-o", str(out))
    assert len(setups_of(out)[1]) == 3 and "3 set-ups" in proc.stderr
