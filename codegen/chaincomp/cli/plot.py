"""``chaincomp plot``: error maps over two axes, the time plot of a replay CSV, and an error
that varies along an axis (a table and its interpolant, or a polynomial)."""

from __future__ import annotations

import csv
import sys

import numpy as np

from ..errors import ChaincompError
from ..jets import JetModel
from ..numeric import ExactModel
from ..units import UNITS
from .common import (MODEL_NAMES, add_machine_argument, add_model_argument, add_values_arguments, check_image,
                     integer, load, parse_number, values_for)

COMPONENTS = ("dx", "dy", "dz", "dkx", "dky", "dkz", "norm")
# 1000 x 1000 points: 4-5 s for one model, 39 s for exact minus second (five_axis_ac, 2026-12)
MAX_GRID = 1000
MODELS = ("first", "second", "exact", "second-first", "exact-first", "exact-second")   # internal names
ORDERS = ("1", "2", "exact", "2-1", "exact-1", "exact-2")   # the same, as --order takes them


def add_parser(sub) -> None:
    p = sub.add_parser("plot", help="error map over two axes, a replay CSV, or an error table",
                       description="Plot one tool-error component over a grid of two axes (the paper's "
                                   "Fig. 3 is dy over Ap and Cp), for the first-order, second-order or "
                                   "exact model or the difference of two; or, with --replay, commanded "
                                   "axes, correction and residual over time from a 'chaincomp replay' CSV; "
                                   "or, with --table P.yaml --error NAME, an error that varies along an "
                                   "axis: its points and its interpolant (or polynomial) with the slope, "
                                   "past both ends to show what happens outside (MACHINE.yaml optional: "
                                   "given, the entry is checked against it).")
    add_machine_argument(p, optional=True)
    add_values_arguments(p)
    p.add_argument("--component", default="dy", choices=COMPONENTS, help="error component (default dy)")
    p.add_argument("--over", metavar="A1,A2", help="the two axes of the map (default: the first two axes)")
    p.add_argument("--range", dest="range1", metavar="LO:HI", help="range of the first axis (declared unit; "
                   "default its limits)")
    p.add_argument("--range2", metavar="LO:HI", help="range of the second axis (default: --range, else limits)")
    p.add_argument("--grid", type=integer(2, MAX_GRID), default=41,
                   help=f"points per axis (2 to {MAX_GRID}, default 41)")
    add_model_argument(p, ORDERS, ("--order", "--model"), "model, or a difference of two (e.g. exact-1); "
                       "--model first|second|exact|second-first.. is the older spelling")
    p.add_argument("--style", default="heatmap", choices=("heatmap", "surface"),
                   help="heatmap (default) or a 3-D surface")
    p.add_argument("--replay", metavar="REPLAY.csv", help="plot a replay CSV instead of a map")
    p.add_argument("--table", metavar="P.yaml", help="plot an error of this params file that varies along an "
                   "axis (with --error)")
    p.add_argument("--error", metavar="NAME", help="the error to plot with --table")
    p.add_argument("-o", "--output", default="plot.png", metavar="OUT.png", help="image file (default plot.png)")
    p.set_defaults(run=run)


def _range(text: str, what: str) -> tuple[float, float]:
    parts = text.split(":")
    if len(parts) != 2:
        raise ChaincompError(f"{what} expects LO:HI, got {text!r}")
    try:
        lo, hi = (parse_number(v) for v in parts)
    except ValueError as exc:
        raise ChaincompError(f"{what} expects LO:HI: {exc}") from None
    if not lo < hi:
        raise ChaincompError(f"{what}: LO must be below HI, got {text!r}")
    return lo, hi


def error_grid(machine, values: dict, over: tuple[str, str], ranges, grid: int, component: str, model: str):
    """(g1, g2, Z): axis values (declared units) and the component on the grid, Z in the
    machine's length unit (direction components unitless)."""
    a1, a2 = (machine.symbol(n) for n in over)
    g1 = np.linspace(*ranges[0], grid)
    g2 = np.linspace(*ranges[1], grid)
    G1, G2 = np.meshgrid(g1, g2, indexing="ij")
    v = dict(values)
    v[a1.name] = a1.to_internal(G1)
    v[a2.name] = a2.to_internal(G2)
    scale = 1.0 / UNITS[machine.length_unit].to_internal
    needs = set(model.split("-"))
    truncated = JetModel(machine, 2) if needs & {"first", "second"} else None
    parts = {}
    for name in needs:
        if name == "exact":
            dp, dd = ExactModel(machine).error(v)
        else:
            dp, dd = truncated.error(v, 1 if name == "first" else 2)
        parts[name] = _component(dp, dd, component, scale, G1.shape)
    z = parts[model.split("-")[0]] - (parts[model.split("-")[1]] if "-" in model else 0)
    return g1, g2, z


def _component(dp, dd, component, scale, shape):
    if component in ("dkx", "dky", "dkz"):
        if dd is None:
            raise ChaincompError("this machine has no tool direction: use dx, dy, dz or norm")
        return np.broadcast_to(np.asarray(dd["xyz".index(component[-1])], float), shape)
    if component == "norm":
        return np.sqrt(sum(np.broadcast_to(np.asarray(c, float), shape) ** 2 for c in dp)) * scale
    return np.broadcast_to(np.asarray(dp["xyz".index(component[-1])], float), shape) * scale


def run(args) -> int:
    import matplotlib
    matplotlib.use("Agg")
    check_image(args.output, args.machine, args.params, args.replay, args.table)
    internal = {v: k for k, v in MODEL_NAMES.items()}
    args.model = "-".join(internal[m] for m in args.model.split("-"))
    if args.replay:
        _plot_replay(args.replay, args.output)
    elif args.table or args.error:
        _plot_table(args)
    else:
        if not args.machine:
            raise ChaincompError("give a MACHINE.yaml (or --replay REPLAY.csv)")
        _plot_map(args)
    print(f"plot: wrote {args.output}", file=sys.stderr)
    return 0


def _plot_map(args) -> None:
    import matplotlib.pyplot as plt
    machine = load(args.machine)
    names = [a.name for a in machine.axes]
    over = tuple(args.over.split(",")) if args.over else tuple(names[:2])
    if len(over) != 2 or over[0] == over[1] or any(n not in names for n in over):
        raise ChaincompError(f"--over expects two different axes of {machine.name} ({', '.join(names)}), "
                             f"got {args.over!r}")
    r1 = _range(args.range1, "--range") if args.range1 else machine.symbol(over[0]).limits
    r2 = _range(args.range2, "--range2") if args.range2 else (
        _range(args.range1, "--range") if args.range1 else machine.symbol(over[1]).limits)
    values, _ = values_for(machine, args.params, args.sets)
    g1, g2, z = error_grid(machine, values, over, (r1, r2), args.grid, args.component, args.model)
    bad = np.argwhere(~np.isfinite(z))
    if len(bad):
        i, j = bad[0]
        raise ChaincompError(f"{args.component} is not finite at {over[0]} = {g1[i]:g}, {over[1]} = {g2[j]:g}: the "
                             "machine's expressions or the values given leave their domain there")
    unit = "" if args.component.startswith("dk") else machine.length_unit
    if unit == "mm":
        z, unit = z * 1000.0, "µm"
    a1, a2 = machine.symbol(over[0]), machine.symbol(over[1])
    fig = plt.figure(figsize=(8, 6), dpi=100)
    label = f"{args.component} [{unit}]" if unit else args.component
    if args.style == "surface":
        ax = fig.add_subplot(projection="3d")
        G1, G2 = np.meshgrid(g1, g2, indexing="ij")
        ax.plot_surface(G1, G2, z, cmap="viridis")
        ax.set_zlabel(label)
    else:
        ax = fig.add_subplot()
        mesh = ax.pcolormesh(g1, g2, z.T, shading="auto", cmap="viridis")
        fig.colorbar(mesh, ax=ax, label=label)
    ax.set_xlabel(f"{a1.name} [{a1.unit.name}]")
    ax.set_ylabel(f"{a2.name} [{a2.unit.name}]")
    names = {"first": "first-order", "second": "second-order", "exact": "exact"}
    model = " minus ".join(names[m] for m in args.model.split("-"))
    ax.set_title(f"{machine.name}: {args.component}, {model} model")
    fig.savefig(args.output)
    plt.close(fig)


def _plot_replay(path: str, output: str) -> None:
    import matplotlib.pyplot as plt
    rows, cols = _read_replay_csv(path)
    ok = cols.pop("ok")
    t = cols.pop("utime")
    t = (t - t[0]) * 1e-6
    residual = cols.pop("residual_point_mm")
    axes = [c[len("commanded_"):] for c in cols if c.startswith("commanded_")]
    fig, (top, mid, bottom) = plt.subplots(3, 1, figsize=(9, 8), dpi=100, sharex=True)
    for a in axes:
        top.plot(t, cols["commanded_" + a], label=a)
        unit = a.rsplit("_", 1)[-1]
        mid.plot(t, cols["correction_" + a] * (1000.0 if unit == "mm" else 3600.0),
                 label=f"{a.rsplit('_', 1)[0]} [{'µm' if unit == 'mm' else 'arcsec'}]")
    bottom.plot(t, residual * 1e6)
    top.set_ylabel("commanded")
    mid.set_ylabel("correction")
    bottom.set_ylabel("residual [nm]")
    bottom.set_xlabel("time [s]")
    top.legend(loc="upper right", fontsize="small")
    mid.legend(loc="upper right", fontsize="small")
    top.set_title(f"replay of {path}: {ok} corrected, {rows - ok} rejected")
    fig.tight_layout()
    fig.savefig(output)
    plt.close(fig)


def _read_replay_csv(path: str) -> tuple[int, dict[str, np.ndarray]]:
    """(rows, {"ok": count, column: values of the corrected records}) of a replay CSV: utime,
    residual_point_mm and every commanded_/correction_ column, each cell a finite number."""
    def fail(message: str, line: int | None = None, field: str | None = None):
        raise ChaincompError(message, path, line, field)

    try:
        with open(path, newline="", encoding="utf-8") as f:
            reader = csv.DictReader(f)
            names = reader.fieldnames or []
            wanted = ["utime", "residual_point_mm"] + [c for c in names if c.startswith(("commanded_", "correction_"))]
            missing = [c for c in ("result", "utime", "residual_point_mm") if c not in names]
            if missing or not any(c.startswith("commanded_") for c in names):
                fail(f"not a 'chaincomp replay' CSV: no {(missing or ['commanded_*'])[0]} column", 1)
            out: dict[str, list[float]] = {c: [] for c in wanted}
            rows = 0
            for row in reader:
                rows += 1
                if row.get("result") != "ok":
                    continue
                for c in wanted:
                    try:
                        out[c].append(parse_number(row.get(c) or ""))
                    except ValueError as exc:
                        fail(str(exc), reader.line_num, c)
    except OSError as exc:
        fail(f"cannot read: {exc.strerror}")
    except UnicodeDecodeError as exc:
        fail(f"not UTF-8 text (byte 0x{exc.object[exc.start]:02x})")
    except csv.Error as exc:
        fail(f"not a CSV file: {exc}")
    if not out["utime"]:
        fail("no corrected records to plot (is it a 'chaincomp replay' CSV?)")
    cols = {c: np.array(v) for c, v in out.items()}
    cols["ok"] = len(out["utime"])
    return rows, cols


def _plot_table(args) -> None:
    """Points, interpolant and slope of one varying error, 5 % past both ends."""
    import matplotlib.pyplot as plt
    from ..varying import Table, parse_varying
    from ..yamlsource import load_yaml
    if not (args.table and args.error):
        raise ChaincompError("--table P.yaml and --error NAME go together")
    machine = load(args.machine) if args.machine else None
    doc = load_yaml(args.table)
    values = doc.get("values") if isinstance(doc, dict) else None
    if not isinstance(values, dict) or args.error not in values:
        raise ChaincompError(f"no values.{args.error} in this file", args.table)
    raw = values[args.error]
    if not isinstance(raw, dict):
        raise ChaincompError(f"{args.error} is a constant here, not a table or polynomial", args.table,
                             values.lines[args.error], f"values.{args.error}")
    if machine is not None:
        from ..params import load_params
        v = load_params(args.table, machine)[args.error]  # the whole file checked against the machine
    else:
        v = parse_varying(raw, args.error, args.table, values.lines[args.error])
    pu, vu = v.units
    if isinstance(v, Table):
        lo, hi = v.x[0], v.x[-1]
    elif np.isfinite(v.lower):
        lo, hi = v.lower, v.upper
    elif machine is not None:
        lo, hi = (machine.symbol(v.axis).to_internal(x) for x in machine.symbol(v.axis).limits)
    else:
        raise ChaincompError(f"{args.error} is a polynomial without a range: give the MACHINE.yaml to plot it "
                             "over the axis limits")
    pad = 0.05 * (hi - lo)
    t = np.linspace(lo - pad, hi + pad, 4001)
    value, slope = v._value_slope(t)
    # nan outside the range is 'outside: reject' (drawn as a gap); inf is an overflow
    bad = np.isinf(value) | np.isinf(slope) | ((t >= lo) & (t <= hi) & ~np.isfinite(value + slope))
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise ChaincompError(f"{args.error} is not finite at {v.axis} = {t[k] / pu.to_internal:g} {pu.name}",
                             args.table, values.lines[args.error], f"values.{args.error}")
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(9, 7), dpi=100, sharex=True,
                                      gridspec_kw={"height_ratios": [3, 2]})
    top.plot(t / pu.to_internal, value / vu.to_internal, lw=1.2,
             label="interpolant" if isinstance(v, Table) else "polynomial")
    if isinstance(v, Table):
        top.plot(v.x / pu.to_internal, v.y / vu.to_internal, "o", ms=3, label=f"{len(v.x)} points")
    for ax in (top, bottom):
        ax.axvspan((lo - pad) / pu.to_internal, lo / pu.to_internal, color="0.9")
        ax.axvspan(hi / pu.to_internal, (hi + pad) / pu.to_internal, color="0.9")
        ax.grid(alpha=0.3)
    bottom.plot(t / pu.to_internal, slope / vu.to_internal * pu.to_internal, lw=1.0, color="C2")
    top.set_ylabel(f"{args.error} [{vu.name}]")
    bottom.set_ylabel(f"slope [{vu.name}/{pu.name}]")
    bottom.set_xlabel(f"{v.axis} [{pu.name}]")
    top.legend(loc="best", fontsize="small")
    top.set_title(f"{args.error}: {v.describe()}\n(shaded: outside the {'table' if isinstance(v, Table) else 'range'})",
                  fontsize="medium")
    fig.tight_layout()
    fig.savefig(args.output)
    plt.close(fig)
