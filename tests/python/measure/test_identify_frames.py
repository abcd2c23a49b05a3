"""identify from full poses (issue #17 item 5): a six-DOF tracker's tool point and tool frame
orientation (a unit quaternion qw, qx, qy, qz in the base frame), simulate-measurements writing
them, and the refusals of bad orientation columns.

Truth from outside the code: the UR5 with base and tool 6-DOF error blocks (tools/bench_machines/
ur5_blocks.yaml, given the flange frame) as a numpy product of DH matrices (test_identify_arm's,
extended to the frame); quaternions made here by Bar-Itzhack's eigenvector method (not the
formula chaincomp uses); the rotation log written here from the angle's arccos and the skew
part; the identifiable rank from this file's SVD of a central-difference Jacobian of that
product.
"""

import json
import math

import numpy as np
import pytest

from chaincomp import load_machine, load_params
from chaincomp.cli.main import main
from chaincomp.measure.identify import residuals
from chaincomp.measure.table import read_table

from helpers import ROOT

ARCSEC, DEG = math.pi / 648000, math.pi / 180
SIG_P, SIG_W = 0.02, 10 * ARCSEC         # mm per coordinate, rad per rotation-vector component
POINT = np.array([30.0, 0.0, 120.0, 1.0])
DH = [  # d, a, alpha (mm, mm, deg): UR's published UR5 table
    (89.159, 0.0, 90.0), (0.0, -425.0, 0.0), (0.0, -392.25, 0.0),
    (109.15, 0.0, 90.0), (94.65, 0.0, -90.0), (82.3, 0.0, 0.0)]


def _rot(i, j, a):
    a = np.asarray(a, float)
    m = np.zeros(a.shape + (4, 4))
    m[..., 0, 0] = m[..., 1, 1] = m[..., 2, 2] = m[..., 3, 3] = 1.0
    c, s = np.cos(a), np.sin(a)
    m[..., i, i], m[..., i, j], m[..., j, i], m[..., j, j] = c, -s, s, c
    return m


def tr(x, y, z):
    x, y, z = np.broadcast_arrays(*(np.asarray(v, float) for v in (x, y, z)))
    m = np.zeros(x.shape + (4, 4))
    m[..., 0, 0] = m[..., 1, 1] = m[..., 2, 2] = m[..., 3, 3] = 1.0
    m[..., 0, 3], m[..., 1, 3], m[..., 2, 3] = x, y, z
    return m


def block(dx, dy, dz, ex, ey, ez):
    """The error block of order txyz: T(dx,dy,dz) Rx(ex) Ry(ey) Rz(ez)."""
    return tr(dx, dy, dz) @ _rot(1, 2, ex) @ _rot(2, 0, ey) @ _rot(0, 1, ez)


def names(m):
    return [s.name for s in m.errors]


def poses(rng, n):
    return np.round(rng.uniform(-180, 180, (6, n)), 4)        # degrees, as written to the CSV


@pytest.fixture(scope="module")
def framed(tmp_path_factory):
    """ur5_blocks.yaml (36 errors: base block, 24 DH, tool block) with the flange frame as tool frame."""
    text = open(f"{ROOT}/tools/bench_machines/ur5_blocks.yaml").read()
    assert text.rstrip().endswith("direction: [0, 0, 1]")
    path = tmp_path_factory.mktemp("framed") / "ur5_blocks_frame.yaml"
    path.write_text(text.rstrip() + "\n  reference: [1, 0, 0]\n")
    return str(path)


def ur5(q, e):
    """(R (rows, 3, 3), p (rows, 3)): the numpy UR5's tool frame and point."""
    m = block(e["bx"], e["by"], e["bz"], e["ba"], e["bb"], e["bc"])
    for i, (d, a, al) in enumerate(DH, 1):
        m = m @ _rot(0, 1, q[i - 1] + e[f"dth{i}"]) @ tr(0, 0, d + e[f"dd{i}"]) @ tr(a + e[f"da{i}"], 0, 0) \
            @ _rot(1, 2, al * DEG + e[f"dal{i}"])
    m = m @ block(e["tx"], e["ty"], e["tz"], e["ta"], e["tb"], e["tc"])
    return m[..., :3, :3], (m @ POINT)[..., :3]


def rotlog(r):
    """Rotation vectors (..., 3) of rotation matrices: angle from the trace, axis from the skew part."""
    v = np.stack([r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0], r[..., 1, 0] - r[..., 0, 1]], -1)
    angle = np.arccos(np.clip((np.trace(r, axis1=-2, axis2=-1) - 1) / 2, -1, 1))
    s = np.sin(angle)
    f = np.where(s < 1e-6, 0.5 + angle ** 2 / 12, angle / (2 * np.where(s < 1e-6, 1, s)))
    return f[..., None] * v


def expm(w):
    """exp([w]x) by the eigen-free series to 30 terms (w small or moderate)."""
    k = np.zeros(w.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -w[..., 2], w[..., 1], -w[..., 0]
    k = k - np.swapaxes(k, -1, -2)
    out, term = np.broadcast_to(np.eye(3), k.shape).copy(), np.broadcast_to(np.eye(3), k.shape).copy()
    for n in range(1, 30):
        term = term @ k / n
        out = out + term
    return out


def quaternion(r):
    """Unit quaternions (qw, qx, qy, qz) of rotation matrices: the eigenvector of the largest
    eigenvalue of Bar-Itzhack's symmetric 4x4 matrix."""
    out = []
    for m in r:
        (a, b, c), (d, e, f), (g, h, i) = m.T      # his matrix is of the transposed (passive) rotation
        k = np.array([[a - e - i, d + b, g + c, f - h], [d + b, e - a - i, h + f, g - c],
                      [g + c, h + f, i - a - e, b - d], [f - h, g - c, b - d, a + e + i]]) / 3
        vals, vecs = np.linalg.eigh(k)
        x, y, z, w = vecs[:, -1]
        out.append(np.array([w, x, y, z]) * (1 if w >= 0 else -1))
    return np.array(out)


def zero(m, rows):
    return {n: np.zeros(rows) for n in names(m)}


def write_csv(path, q_deg, p=None, quat=None):
    head = [f"q{i}" for i in range(1, 7)] + (["x", "y", "z"] if p is not None else []) \
        + (["qw", "qx", "qy", "qz"] if quat is not None else [])
    lines = ["# simulated six-DOF tracker data", ",".join(head)]
    for r in range(q_deg.shape[1]):
        cells = [repr(float(v)) for v in q_deg[:, r]]
        cells += [repr(float(v)) for v in p[r]] if p is not None else []
        cells += [repr(float(v)) for v in quat[r]] if quat is not None else []
        lines.append(",".join(cells))
    path.write_text("\n".join(lines) + "\n")
    return path


def run(capsys, *args):
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def own_rank(m, q, orientation=True):
    """Rank of this file's central-difference Jacobian of the point (/SIG_P) and, if asked, of
    the frame's rotation vector (/SIG_W), columns scaled to unit norm (singular values above
    1e-6 of the largest, as test_identify_arm counts)."""
    rows = q.shape[1]
    r0, _ = ur5(q, zero(m, rows))
    cols = []
    for n in names(m):
        plus, minus = zero(m, rows), zero(m, rows)
        plus[n] += 1e-6
        minus[n] -= 1e-6
        (rp, pp), (rm, pm) = ur5(q, plus), ur5(q, minus)
        dp = (pp - pm) / 2e-6
        dw = (rotlog(rp @ np.swapaxes(r0, -1, -2)) - rotlog(rm @ np.swapaxes(r0, -1, -2))) / 2e-6
        cols.append(np.concatenate([dp / SIG_P] + ([dw / SIG_W] if orientation else []), axis=1).ravel())
    j = np.array(cols).T
    s = np.linalg.svd(j / np.linalg.norm(j, axis=0), compute_uv=False)
    return int((s > 1e-6 * s[0]).sum())


@pytest.fixture(scope="module")
def truth(framed):
    m = load_machine(framed)
    rng = np.random.default_rng(1717)
    chosen = set(rng.choice(names(m), 30, replace=False))
    values = {n: (rng.normal(0, 0.15) if m.symbol(n).unit.name == "um" else rng.normal(0, 60) * ARCSEC)
              if n in chosen else 0.0 for n in names(m)}
    return m, rng, values


def measure(m, rng, values, n):
    q_deg = poses(rng, n)
    r, p = ur5(q_deg * DEG, {k: np.full(n, v) for k, v in values.items()})
    p = p + SIG_P * rng.standard_normal((n, 3))
    r = expm(SIG_W * rng.standard_normal((n, 3))) @ r
    return q_deg, p, quaternion(r)


def test_full_poses_identify_more_than_points_and_predict_held_out_poses(framed, truth, tmp_path, capsys):
    """30 injected errors (DH, base and tool blocks), 50 full poses with 0.02 mm and 10 arcsec
    noise: the rank is this file's own and above the points' alone, the minimal set has that
    many parameters, chi2/dof near 1, and at 50 held-out poses the fitted model's point and
    orientation are within 3 sigma of the truth."""
    m, rng, values = truth
    q_deg, p, quat = measure(m, rng, values, 50)
    assert sum(v != 0 for v in values.values()) == 30
    csv = write_csv(tmp_path / "meas.csv", q_deg, p, quat)
    out = tmp_path / "fit.yaml"
    rc, text, err = run(capsys, "identify", framed, csv, "--minimal", "--sigma", "20um,10arcsec", "--format", "json",
                        "-o", out)
    assert rc == 0, err
    doc = json.loads(text)
    rank = own_rank(m, q_deg * DEG)
    points_only = own_rank(m, q_deg * DEG, orientation=False)
    assert doc["rank"] == rank > points_only
    assert doc["minimal"] and len(doc["estimates"]) == rank < 36
    assert doc["measured"] == ["x", "y", "z", "wx", "wy", "wz"] and doc["observations"] == 300
    assert doc["sigma"]["wx"] == {"value": pytest.approx(SIG_W, rel=1e-12), "unit": "rad"}
    assert 0.7 < doc["chi2_per_dof"] < 1.4
    assert 0.7 * SIG_W < doc["rms_orientation_residual"] < 1.3 * SIG_W
    for n, r in doc["redundant"].items():
        assert r["carried_by"] and set(r["carried_by"]) <= set(doc["estimates"]), n

    # the points alone see fewer combinations (identify agrees with the numpy rank there too)
    write_csv(tmp_path / "points.csv", q_deg, p)
    rc, text, err = run(capsys, "identify", framed, tmp_path / "points.csv", "--minimal", "--format", "json")
    assert rc == 0, err
    assert json.loads(text)["rank"] == points_only

    fitted = load_params(str(out), m)
    q_new = poses(rng, 50) * DEG
    r_true, p_true = ur5(q_new, {k: np.full(50, v) for k, v in values.items()})
    r_fit, p_fit = ur5(q_new, {n: np.full(50, fitted[n]) for n in names(m)})
    r_nom, p_nom = ur5(q_new, zero(m, 50))
    assert np.abs(p_fit - p_true).max() <= 3 * SIG_P
    w = rotlog(r_fit @ np.swapaxes(r_true, -1, -2))
    assert np.abs(w).max() <= 3 * SIG_W
    assert np.abs(rotlog(r_nom @ np.swapaxes(r_true, -1, -2))).max() > 30 * SIG_W   # the errors mattered


def test_the_orientation_residual_is_the_rotation_log(framed, tmp_path):
    """identify's residual of a measured orientation is log(R_measured R_model^T) about the base
    axes, also for large turns (up to 2.5 rad) where a first-order difference would be wrong."""
    m = load_machine(framed)
    rng = np.random.default_rng(3)
    n = 40
    q_deg = poses(rng, n)
    errs = {k: np.full(n, v) for k, v in zip(names(m), rng.normal(0, 1e-3, 36))}
    r_model, p_model = ur5(q_deg * DEG, errs)
    turn = rng.normal(0, 1, (n, 3))
    turn *= (rng.uniform(0, 2.5, n) / np.linalg.norm(turn, axis=1))[:, None]
    r_meas = expm(turn) @ r_model
    table = read_table(str(write_csv(tmp_path / "m.csv", q_deg, p_model + 0.5, quaternion(r_meas))), m)
    res = residuals(m, table, {k: v[0] for k, v in errs.items()})
    assert np.allclose(res[:, :3], 0.5, atol=1e-9)
    assert np.isnan(res[:, 3:6]).all()                        # no direction measured
    assert np.abs(res[:, 6:] - rotlog(r_meas @ np.swapaxes(r_model, -1, -2))).max() < 1e-12
    assert np.abs(res[:, 6:] - turn).max() < 1e-12
    # quaternions rounded to 4 decimals (norm off by up to 2e-4) are read, normalised
    rounded = np.round(quaternion(r_meas), 4)
    table = read_table(str(write_csv(tmp_path / "r.csv", q_deg, p_model, rounded)), m)
    res = residuals(m, table, {k: v[0] for k, v in errs.items()})
    want = rotlog(r_meas @ np.swapaxes(r_model, -1, -2))
    assert 1e-6 < np.abs(res[:, 6:] - want).max() < 4e-4


def test_simulate_measurements_writes_the_frame_with_angular_noise(framed, truth, tmp_path, capsys):
    m, _, values = truth
    params = tmp_path / "p.yaml"
    params.write_text("machine: ur5_blocks\nvalues:\n" + "".join(
        f"  {n}: \"{v / m.symbol(n).unit.to_internal!r} {m.symbol(n).unit.name}\"\n" for n, v in values.items()))
    rc, _, err = run(capsys, "simulate-measurements", framed, "--params", params, "--setups", "random:400",
                     "--measure", "x,y,z,q", "-o", tmp_path / "exact.csv")
    assert rc == 0, err
    data = np.loadtxt(tmp_path / "exact.csv", delimiter=",", comments="#", skiprows=3)
    header = open(tmp_path / "exact.csv").read().splitlines()[2].split(",")
    assert header == [f"q{i}" for i in range(1, 7)] + ["x", "y", "z", "qw", "qx", "qy", "qz"]
    r, p = ur5(data[:, :6].T * DEG, {k: np.full(400, v) for k, v in values.items()})
    assert np.abs(data[:, 6:9] - p).max() < 1e-9
    q = quaternion(r)
    assert np.abs(data[:, 9:] - q).max() < 1e-12 and (data[:, 9] >= 0).all()
    rc, _, err = run(capsys, "simulate-measurements", framed, "--params", params, "--setups", "random:400",
                     "--measure", "qw,qx,qy,qz", "--angle-noise", "10arcsec", "-o", tmp_path / "noisy.csv")
    assert rc == 0, err
    noisy = np.loadtxt(tmp_path / "noisy.csv", delimiter=",", comments="#", skiprows=3)
    assert np.array_equal(noisy[:, :6], data[:, :6])          # the same seed: the same set-ups
    r_noisy = np.array([np.eye(3)] * 400)
    w, x, y, z = noisy[:, 6:].T                                # the quaternion's matrix, written out here
    r_noisy = np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
                        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
                        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], -2)
    dev = rotlog(r_noisy @ np.swapaxes(r, -1, -2))
    assert 0.9 * SIG_W < dev.std() < 1.1 * SIG_W and abs(dev.mean()) < 0.2 * SIG_W


# ---------------------------------------------------------------- refusals

GOOD = "0.5,0.5,0.5,0.5"


@pytest.mark.parametrize("cells, field, words", [
    ("0.5,0.5,0.5,0.6", "qw", "not a unit quaternion (norm 1.05357, expected 1 within 0.001)"),
    ("1.1,0,0,0", "qw", "not a unit quaternion"),
    ("nan,0,0,1", "qw", "expected a finite number, got 'nan'"),
    ("0.5,inf,0.5,0.5", "qx", "expected a finite number, got 'inf'"),
    ("0.5,0.5,,0.5", "qy", "needs all four quaternion components"),
    ("0,0,0,0", "qw", "not a unit quaternion (norm 0"),
])
def test_bad_quaternions_are_refused_with_line_and_column(framed, tmp_path, capsys, cells, field, words):
    q_deg = poses(np.random.default_rng(1), 12)
    rows = [",".join([repr(float(v)) for v in q_deg[:, r]] + [GOOD if r != 4 else cells]) for r in range(12)]
    path = tmp_path / "bad.csv"
    path.write_text("q1,q2,q3,q4,q5,q6,qw,qx,qy,qz\n" + "\n".join(rows) + "\n")
    rc, _, err = run(capsys, "identify", framed, path)
    assert rc == 2 and "Traceback" not in err, err
    assert f"{path}:6: {field}: " in err and words in err, err
    assert len(err.strip().splitlines()) == 1


@pytest.mark.slow
def test_orientation_columns_refused_where_they_cannot_mean_anything(framed, tmp_path, capsys):
    q_deg = poses(np.random.default_rng(2), 12)
    body = "\n".join(",".join([repr(float(v)) for v in q_deg[:, r]] + [GOOD]) for r in range(12)) + "\n"
    # a machine without a frame (the same arm, its frame taken out)
    plain = tmp_path / "plain.yaml"
    plain.write_text(open(framed).read().replace("  reference: [1, 0, 0]\n", ""))
    (tmp_path / "q.csv").write_text("q1,q2,q3,q4,q5,q6,qw,qx,qy,qz\n" + body)
    rc, _, err = run(capsys, "identify", plain, tmp_path / "q.csv")
    assert rc == 2 and f"{tmp_path / 'q.csv'}:1: header: column 'qw' is a measured tool frame orientation" in err
    assert "has no tool frame" in err
    # three of the four columns
    (tmp_path / "q3.csv").write_text("q1,q2,q3,q4,q5,q6,qw,qx,qy\n" + body.replace(",0.5\n", "\n"))
    rc, _, err = run(capsys, "identify", framed, tmp_path / "q3.csv")
    assert rc == 2 and ":1: header: " in err and "missing qz" in err, err
    # the direction and the quaternion together (the quaternion holds the direction)
    both = "q1,q2,q3,q4,q5,q6,kx,ky,kz,qw,qx,qy,qz\n" + body.replace(GOOD, "0,0,1," + GOOD)
    (tmp_path / "both.csv").write_text(both)
    rc, _, err = run(capsys, "identify", framed, tmp_path / "both.csv")
    assert rc == 2 and ":1: header: " in err and "both measure the tool axis" in err, err
    # simulate-measurements: no frame, bad names, an angle noise without a unit or an orientation
    out = tmp_path / "o.csv"
    for machine, args, words in [
        (plain, ["--measure", "x,q"], "has no tool frame"),
        (framed, ["--measure", "x,qw,qx"], "as q or as all four of qw, qx, qy, qz"),
        (framed, ["--measure", "q", "--angle-noise", "10"], "give the unit"),
        (framed, ["--measure", "q", "--angle-noise=-1arcsec"], "zero or positive"),
        (framed, ["--measure", "q", "--angle-noise", "1um"], "length unit"),
        (framed, ["--angle-noise", "1arcsec"], "no orientation is measured"),
    ]:
        rc, _, err = run(capsys, "simulate-measurements", machine, "--setups", "random:5", *args, "-o", out)
        assert rc == 2 and "Traceback" not in err and words in err, (args, err)
    # --sigma with an angle, but neither a direction nor an orientation measured
    rc, _, err = run(capsys, "simulate-measurements", framed, "--setups", "random:60", "-o", out)
    assert rc == 0, err
    rc, _, err = run(capsys, "identify", framed, out, "--sigma", "20um")
    assert rc == 0, err
    rc, _, err = run(capsys, "identify", framed, out, "--sigma", "20um,10arcsec")
    assert rc == 2 and "no kx, ky, kz (or qw, qx, qy, qz) column" in err, err
