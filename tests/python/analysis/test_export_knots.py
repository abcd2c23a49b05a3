"""LinuxCNC tables fitted to a params table whose knots fall between the exported entries (issue
#42 item 5): the report checks at the params' own knots too, and counts each check point once.

Truth from outside the exporter: the tests' own gantry (test_export.OWN, its tool point written
by hand), EXX linear between the knots written below (numpy's interp, held outside), the table
read back by linuxcnc_comp.py (LinuxCNC's reader and interpolation) and the check points built
here as the guide describes them (docs/guide/export.md, Check points)."""

import numpy as np
import pytest

import linuxcnc_comp
from test_export import export, own_model

KNOTS = np.array([0.0, 40.0, 100.0, 170.0, 230.0, 300.0])   # mm: none on the entries 75, 150, 225
VALUES = np.array([0.0, 3.0, -2.0, 2.5, -1.5, 1.0]) * 1e-3    # mm
TABLE = "machine: own_xyz\nvalues:\n  EXX:\n    axis: X\n    units: [mm, um]\n    interpolation: linear\n" \
        "    outside: hold\n    table:\n" + "".join(f"      - [{x:g}, {v * 1e3:g}]\n" for x, v in zip(KNOTS, VALUES))
LIMITS = [(0, 300), (0, 200), (-100, 0)]
GRID, ENTRIES = 3, 5


def exx(x):
    return np.interp(x, KNOTS, VALUES)


def points(along_x=None):
    """Distinct check points: the grid, and along each joint its entries' midpoints x the grid
    of the others, and along X the knots x the grid of the others (or only ``along_x``)."""
    axes = [np.linspace(lo, hi, GRID) for lo, hi in LIMITS]
    runs = []
    if along_x is None:
        runs.append(axes)
        for j, (lo, hi) in enumerate(LIMITS):
            e = np.linspace(lo, hi, ENTRIES)
            runs.append([(e[1:] + e[:-1]) / 2 if k == j else a for k, a in enumerate(axes)])
        runs.append([KNOTS] + axes[1:])
    else:
        runs.append([along_x] + axes[1:])
    pts = {tuple(np.round(p, 9)) for run in runs for p in zip(*(m.ravel() for m in np.meshgrid(*run, indexing="ij")))}
    return np.array(sorted(pts)).T


def test_the_residual_is_checked_at_the_params_knots_each_point_once(capsys, tmp_path):
    doc, out = export(capsys, tmp_path, TABLE, "linuxcnc-comp", "--grid", str(GRID), "--entries", str(ENTRIES),
                      "--no-breakdown")
    tables = [linuxcnc_comp.read((out / f"joint{n}_{a}.comp").read_text(), 1) for n, a in enumerate("XYZ")]

    def residual(p):
        x, y, z = p
        tx, ty, tz = (linuxcnc_comp.trim(t, v) for t, v in zip(tables, (x, y, z)))
        return np.linalg.norm(own_model(x + tx, y + ty, z + tz, exx) - p, axis=0) * 1e3

    p = points()
    # 27 grid + 3 joints x 4 midpoints x 9 + 6 knots x 9 = 189, the knots 0 and 300 on the grid
    assert p.shape[1] == 171 and doc["check_points"] == 171
    assert doc["after"]["max_um"] == pytest.approx(residual(p).max(), abs=0.01)
    assert doc["before"]["max_um"] == pytest.approx(np.abs(exx(p[0])).max() * 1e3, abs=0.01)
    # the knots hold the largest residual: the grid and the midpoints alone would report less
    at_knots = residual(points(KNOTS)).max()
    assert at_knots == pytest.approx(residual(p).max(), abs=1e-9)
    others = residual(p[:, ~np.isin(np.round(p[0], 9), KNOTS)]).max()
    assert others < at_knots - 0.1
    # and densely along X (the residual is linear between knots and entries): nothing larger
    dense = residual(points(np.linspace(0, 300, 3001)))
    assert dense.max() <= doc["after"]["max_um"] + 0.01
