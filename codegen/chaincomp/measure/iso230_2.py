"""ISO 230-2:2014 evaluation of the positioning of one axis from repeated bidirectional runs
(a laser interferometer's readings), and the CSV those runs come in.

The CSV (read by ``model.csvtable``, the rules of every CSV a verb reads): one row per reading,
a header row naming the columns, ``#`` lines and blank lines ignored (line numbers still count
them)::

    # X axis, 5 bidirectional runs
    target [mm],run,direction,deviation [um]
    0,1,up,0.12
    0,1,down,1.31
    ...

Columns (case-insensitive; others are ignored): ``target`` (the target position P_i),
``run`` (1, 2, ... : the approach number j), ``direction`` (``up``/``+``/``↑`` for the positive
direction of approach, ``down``/``-``/``↓`` for the negative), and either ``deviation``
(x_ij = P_ij - P_i) or ``actual`` (the measured position P_ij; the deviation is actual minus
target). Units in brackets or parentheses after a column's name, or from the caller
(``--column-units``); ``column_map`` maps these names onto another program's header.

Every target must have the same runs in both directions, and at least 2 runs (the standard
deviation s needs n >= 2; with n = 1 the file is refused), and there must be 2 targets or more.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ..errors import ChaincompError
from ..model import csvtable, units as U
from ..model.expressions import MAX_LITERAL

FIELDS = ("target", "run", "direction", "deviation", "actual")
UP, DOWN = "up", "down"
_DIRECTIONS = {"up": UP, "+": UP, "↑": UP, "pos": UP, "positive": UP,
               "down": DOWN, "-": DOWN, "↓": DOWN, "neg": DOWN, "negative": DOWN}
# the unit deviations are reported in, per kind (as simulate-calibration's tables)
REPORT_UNIT = {"length": "um", "angle": "arcsec", "ratio": "ppm"}
_RUN = re.compile(r"[0-9]{1,9}")


@dataclass
class Runs:
    """The readings of one axis: deviations [target, run] per direction, in ``unit``."""

    file: str
    targets: np.ndarray        # P_i, increasing, in position_unit
    position_unit: U.Unit
    unit: U.Unit               # unit of the deviations (REPORT_UNIT of their kind)
    runs: list[int]            # run numbers j, increasing
    up: np.ndarray             # x_ij↑, shape (m, n)
    down: np.ndarray           # x_ij↓, shape (m, n)
    lines: np.ndarray          # line of the first reading of each target


@dataclass
class Evaluation:
    """ISO 230-2 figures: per target (arrays of length m) and for the axis."""

    mean_up: np.ndarray        # x̄_i↑
    mean_down: np.ndarray      # x̄_i↓
    mean: np.ndarray           # x̄_i
    reversal: np.ndarray       # B_i
    s_up: np.ndarray           # s_i↑
    s_down: np.ndarray         # s_i↓
    R_up: np.ndarray           # R_i↑ = 4 s_i↑
    R_down: np.ndarray         # R_i↓
    R_i: np.ndarray            # R_i = max(2 s_i↑ + 2 s_i↓ + |B_i|, R_i↑, R_i↓)
    axis: dict                 # B, B_mean, E_up, E_down, E, M, R_up, R_down, R, A_up, A_down, A


def evaluate(runs: Runs) -> Evaluation:
    """The standard's definitions, §3 and §7 of ISO 230-2:2014 (s with n - 1 degrees of freedom)."""
    up, down = runs.up, runs.down
    mu, md = up.mean(axis=1), down.mean(axis=1)
    su, sd = up.std(axis=1, ddof=1), down.std(axis=1, ddof=1)
    b = mu - md
    ru, rd = 4 * su, 4 * sd
    ri = np.maximum.reduce([2 * su + 2 * sd + np.abs(b), ru, rd])
    mean = (mu + md) / 2
    lo_u, hi_u, lo_d, hi_d = mu - 2 * su, mu + 2 * su, md - 2 * sd, md + 2 * sd
    axis = {
        "B": float(np.max(np.abs(b))),
        "B_mean": float(np.mean(b)),
        "E_up": float(np.ptp(mu)),
        "E_down": float(np.ptp(md)),
        "E": float(max(mu.max(), md.max()) - min(mu.min(), md.min())),
        "M": float(np.ptp(mean)),
        "R_up": float(ru.max()),
        "R_down": float(rd.max()),
        "R": float(ri.max()),
        "A_up": float(hi_u.max() - lo_u.min()),
        "A_down": float(hi_d.max() - lo_d.min()),
        "A": float(max(hi_u.max(), hi_d.max()) - min(lo_u.min(), lo_d.min())),
    }
    return Evaluation(mu, md, mean, b, su, sd, ru, rd, ri, axis)


# ----------------------------------------------------------------------------- reading

def parse_column_map(text: str | None, option: str = "--columns") -> dict[str, str]:
    """'target=Target Pos,deviation=Error' -> {field: header name}."""
    out: dict[str, str] = {}
    if not text:
        return out
    for item in text.split(","):
        field, sep, name = item.partition("=")
        field, name = field.strip().lower(), name.strip()
        if not sep or not name:
            raise ChaincompError(f"{option}: expected FIELD=HEADER pairs separated by commas, got {item.strip()!r}")
        if field not in FIELDS:
            raise ChaincompError(f"{option}: unknown field {field!r} (expected one of: {', '.join(FIELDS)})")
        if field in out:
            raise ChaincompError(f"{option}: {field} given twice")
        out[field] = name
    return out


def parse_units(text: str | None, option: str = "--column-units") -> tuple[U.Unit | None, U.Unit | None]:
    """'mm,um' -> (position unit, deviation unit)."""
    if not text:
        return None, None
    parts = [p.strip() for p in text.split(",")]
    if len(parts) != 2:
        raise ChaincompError(f"{option}: expected POSITION,DEVIATION units, e.g. mm,um, got {text!r}")
    try:
        return U.unit(parts[0]), U.unit(parts[1])
    except KeyError as exc:
        raise ChaincompError(f"{option}: {exc.args[0]}") from None


def read_runs(path: str, column_map: dict[str, str] | None = None,
              units: tuple[U.Unit | None, U.Unit | None] = (None, None)) -> Runs:
    """The runs in a CSV file; every fault a ChaincompError naming the file, line and column."""
    table = csvtable.read(path, example="target [mm],run,direction,deviation [um]")
    header, hline = table.header, table.line
    column_map = column_map or {}
    wanted = {f: f for f in FIELDS}
    for mapped, other in (("deviation", "actual"), ("actual", "deviation")):
        if mapped in column_map and other not in column_map:
            del wanted[other]   # mapped one: another column of the default name is not a second value
    wanted.update(column_map)
    col: dict[str, int] = {}
    head_units: dict[str, str | None] = {}
    for field, want in wanted.items():
        for k, cell in enumerate(header):
            name, unit = csvtable.split_unit(cell)
            if want.lower() in (cell.lower(), name.lower()):
                if field in col:
                    raise ChaincompError(f"two columns named {want!r} (columns {col[field] + 1} and {k + 1})",
                                         path, hline, want)
                col[field] = k
                head_units[field] = unit
    taken: dict[int, str] = {}
    for field, k in col.items():
        if k in taken:   # e.g. --columns actual=target: every deviation would be 0
            raise ChaincompError(f"column {k + 1} ({header[k]!r}) is both {taken[k]} and {field}", path,
                                 hline, wanted[field])
        taken[k] = field
    if "deviation" in col and "actual" in col:
        raise ChaincompError("give either a deviation or an actual column, not both", path, hline,
                             wanted["actual"])
    for field in ("target", "run", "direction"):
        if field not in col:
            raise ChaincompError(f"no column {wanted[field]!r} (header: {', '.join(header)}; map other names "
                                 f"with --columns {field}=NAME)", path, hline, wanted[field])
    value = "deviation" if "deviation" in col else "actual" if "actual" in col else None
    if value is None:
        raise ChaincompError(f"no column 'deviation' or 'actual' (header: "
                             f"{', '.join(header)}; map other names with --columns deviation=NAME or "
                             "actual=NAME)", path, hline, "deviation")

    def unit_of(field: str, given: U.Unit | None) -> U.Unit:
        written = head_units.get(field)
        if written is None:
            if given is None:
                raise ChaincompError(f"no unit for column {wanted[field]!r}: write it in the header "
                                     f"('{wanted[field]} [mm]') or give --column-units", path, hline, wanted[field])
            return given
        try:
            u = U.unit(written)
        except KeyError as exc:
            raise ChaincompError(exc.args[0], path, hline, wanted[field]) from None
        if given is not None and given != u:
            raise ChaincompError(f"the header says {u.name}, --column-units says {given.name}", path, hline, wanted[field])
        return u

    pos_unit = unit_of("target", units[0])
    if pos_unit.kind not in ("length", "angle"):   # a slide's or a rotary axis' position
        raise ChaincompError(f"targets in {pos_unit.name}: a target is a length or an angle (mm, deg, ...)",
                             path, hline, wanted["target"])
    if value == "actual":
        # without a unit of its own, the actual position is in the target's unit
        val_unit = pos_unit if head_units.get("actual") is None else unit_of("actual", None)
        if val_unit.kind != pos_unit.kind:
            raise ChaincompError(f"actual positions in {val_unit.name} but targets in {pos_unit.name}",
                                 path, hline, wanted["actual"])
    else:
        val_unit = unit_of("deviation", units[1])
    report = U.unit(REPORT_UNIT[val_unit.kind])

    readings: dict[tuple[float, str, int], float] = {}
    first_line: dict[float, int] = {}
    where: dict[tuple[float, str, int], int] = {}
    for row in table.rows:
        line = row.line

        def cell(field: str) -> str:
            text = row.cells[col[field]]
            if not text:
                raise ChaincompError("missing value", path, line, wanted[field])
            return text

        target = table.number(row, col["target"], wanted["target"])
        run_text = cell("run").strip()
        if not _RUN.fullmatch(run_text) or int(run_text) < 1:
            raise ChaincompError(f"expected a run number 1, 2, ..., got {run_text!r}", path, line, wanted["run"])
        run = int(run_text)
        d = _DIRECTIONS.get(cell("direction").strip().lower())
        if d is None:
            raise ChaincompError(f"expected up or down (or +, -), got {cell('direction').strip()!r}", path, line,
                                 wanted["direction"])
        v = table.number(row, col[value], wanted[value])
        if value == "actual":
            dev = (v * val_unit.to_internal - target * pos_unit.to_internal) / report.to_internal
        else:
            dev = v * val_unit.to_internal / report.to_internal
        # the bound of every value in the project (1e15 mm or rad), so that s and R stay finite
        for field, internal in (("target", target * pos_unit.to_internal), (value, dev * report.to_internal)):
            if not abs(internal) <= MAX_LITERAL:
                raise ChaincompError(f"{cell(field).strip()!r} is larger than {MAX_LITERAL:g} "
                                     f"{U.INTERNAL[pos_unit.kind if field == 'target' else val_unit.kind]} "
                                     "in magnitude", path, line, wanted[field])
        key = (target, d, run)
        if key in readings:
            raise ChaincompError(f"a second reading for target {target:g}, run {run}, {d} (the first on line "
                                 f"{where[key]})", path, line, wanted["run"])
        readings[key] = dev
        where[key] = line
        first_line.setdefault(target, line)
    if not readings:
        raise ChaincompError("no readings below the header", path, hline)

    targets = sorted(first_line)
    runs = sorted({r for (_, _, r) in readings})
    if len(targets) < 2:
        raise ChaincompError(f"only one target position ({targets[0]:g}); ISO 230-2 needs several along the "
                             "axis (at least 5 per metre)", path, first_line[targets[0]], wanted["target"])
    if len(runs) < 2:
        raise ChaincompError("only one run: the standard uncertainty s needs at least 2 runs per direction "
                             "(ISO 230-2 takes 5)", path, hline, wanted["run"])
    for t in targets:
        for d in (UP, DOWN):
            missing = [r for r in runs if (t, d, r) not in readings]
            if missing:
                raise ChaincompError(f"target {t:g} has no reading for run {', '.join(map(str, missing))} {d} "
                                     f"(every target needs runs {', '.join(map(str, runs))} in both directions)",
                                     path, first_line[t], wanted["target"])
    grid = {d: np.array([[readings[(t, d, r)] for r in runs] for t in targets]) for d in (UP, DOWN)}
    return Runs(path, np.array(targets), pos_unit, report, runs, grid[UP], grid[DOWN],
                np.array([first_line[t] for t in targets]))
