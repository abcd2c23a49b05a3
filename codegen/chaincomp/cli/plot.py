"""``chaincomp plot``: error maps over two axes (flat, or as a surface beside the map), the error
over the working volume, the time plot of a replay CSV, an error that varies along an axis (a
table and its interpolant, or a polynomial), and an interactive HTML file of the surface and
the volume. Titles, labels and units come from ``figures`` for every view."""

from __future__ import annotations

import math
import os
import sys
from dataclasses import dataclass

import numpy as np

from ..errors import ChaincompError
from ..escape import html_text
from ..model import csvtable
from ..model.display import add_units_argument, display_unit
from ..model.expressions import MAX_LITERAL
from ..model.units import UNITS
from ..output import write_file
from ..symbolic.jets import JetModel
from ..symbolic.numeric import ExactModel
from ..symbolic.orientation import angle_between
from . import figures as F
from .common import (MODEL_NAMES, add_deprecated, add_machine_argument, add_model_argument, add_values_arguments,
                     check_image, check_output, integer, load, model_choice, parse_number, refuse_empty, values_for)

COMPONENTS = ("dx", "dy", "dz", "dkx", "dky", "dkz", "norm")
# 1000 x 1000 points: 4-5 s for one model, 39 s for exact minus second (five_axis_ac, 2026-12)
MAX_GRID = 1000
MAX_UTIME = 2 ** 62    # µs, as simulate-log writes them: int64 with room for any duration
# a replay CSV: simulate-log's most samples, at about 250 bytes a record
MAX_REPLAY_ROWS, MAX_REPLAY_BYTES = 4_000_000, 1024 ** 3
# arrows in the volume view: 12^3 = 1728 still read as a field, more are a blur
MAX_VOLUME_GRID = 12
VIEWS = ("map", "surface", "volume")
DEFAULT_GRID = {"map": 41, "surface": 41, "volume": 5}
MODELS = ("first", "second", "exact", "second-first", "exact-first", "exact-second")   # internal names
ORDERS = ("1", "2", "exact", "2-1", "exact-1", "exact-2")   # the same, as --order takes them


def add_parser(sub) -> None:
    p = sub.add_parser("plot", help="error map, surface or volume view, a replay CSV, or an error table",
                       description="Plot one tool-error component over a grid of two axes (the paper's "
                                   "Fig. 3 is dy over Ap and Cp), for the first-order, second-order or "
                                   "exact model or the difference of two: as a map, or as a 3-D surface "
                                   "beside the map (--view surface); or the tool point error as arrows at "
                                   "a grid of up to three axes over the working volume (--view volume); or, "
                                   "with --replay, commanded axes, correction and the tool error with and "
                                   "without compensation over time from a 'chaincomp replay' CSV (the "
                                   "error without it needs MACHINE.yaml and --params); or, with --table "
                                   "P.yaml --error NAME, an error that varies along an axis: its points "
                                   "and its interpolant (or polynomial) with the slope, past both ends to "
                                   "show what happens outside (MACHINE.yaml optional: given, the entry is "
                                   "checked against it). --html writes the surface and the volume view "
                                   "as one interactive file. Errors in µm and arcsec (--units internal: "
                                   "mm and rad).")
    add_machine_argument(p, optional=True)
    add_values_arguments(p)
    p.add_argument("--view", choices=VIEWS, help="map (default), surface (a 3-D surface beside the map) or "
                   "volume (arrows of the tool point error over the working volume)")
    add_deprecated(p, "--style", "--view (heatmap is map)", "style", choices=("heatmap", "surface"))
    p.add_argument("--component", default="dy", choices=COMPONENTS,
                   help="error component of the map and surface (default dy; dk*: tilt of the tool axis)")
    p.add_argument("--over", metavar="A1,A2", help="the two axes of the map (default: the first two axes); for "
                   "--view volume one to three axes (default: the linear axes, else the first three)")
    p.add_argument("--range", dest="range1", metavar="LO:HI", help="range of the first axis (declared unit; "
                   "default its limits)")
    p.add_argument("--range2", metavar="LO:HI", help="range of the second axis (default: --range, else limits)")
    p.add_argument("--grid", type=integer(2, MAX_GRID), metavar="N",
                   help=f"points per axis: map and surface 2 to {MAX_GRID} (default 41); volume 2 to "
                        f"{MAX_VOLUME_GRID} (default 5; 3 gives the corners, mid-edges, face centres and centre)")
    add_model_argument(p, ORDERS, ("--order",), "model, or a difference of two (e.g. exact-1)")
    # --model names a compiled library elsewhere (replay, chaincompd)
    add_deprecated(p, "--model", "--order (first, second, exact: 1, 2, exact)", "model", type=model_choice(ORDERS),
                   metavar="first|second|exact|...")
    add_units_argument(p)
    p.add_argument("--replay", metavar="REPLAY.csv", help="plot a replay CSV instead of a map")
    p.add_argument("--table", metavar="P.yaml", help="plot an error of this params file that varies along an "
                   "axis (with --error)")
    p.add_argument("--error", metavar="NAME", help="the error to plot with --table")
    p.add_argument("-o", "--output", metavar="OUT.png",
                   help="image file (default plot.png; none when only --html is given)")
    p.add_argument("--html", metavar="OUT.html", help="write the surface and the volume view as one "
                   "self-contained interactive HTML file (works offline; rotate and zoom in a browser)")
    p.set_defaults(run=run)


def _range(text: str, what: str, axis=None) -> tuple[float, float]:
    """LO:HI in the axis' declared unit; beyond its limits a warning (the machine cannot go there)."""
    parts = text.split(":")
    if len(parts) != 2:
        raise ChaincompError(f"{what} expects LO:HI, got {text!r}")
    try:
        lo, hi = (parse_number(v) for v in parts)
    except ValueError as exc:
        raise ChaincompError(f"{what} expects LO:HI: {exc}") from None
    if not lo < hi:
        raise ChaincompError(f"{what}: LO must be below HI, got {text!r}")
    if max(abs(lo), abs(hi)) > MAX_LITERAL:   # the bound of every value given (and 1e308 overflows)
        raise ChaincompError(f"{what}: values are at most {MAX_LITERAL:g} in magnitude, got {text!r}")
    if axis is not None and (lo < axis.limits[0] or hi > axis.limits[1]):
        F.warn(f"{what} {text}: beyond the limits of {axis.name} [{axis.limits[0]:g}, {axis.limits[1]:g}] "
               f"{axis.unit.name}")
    return lo, hi


def model_error(machine, values: dict, model: str):
    """(dp, dd or None) of a model or a difference of two, internal units, broadcast over values."""
    names = model.split("-")
    truncated = JetModel(machine, 2) if set(names) & {"first", "second"} else None
    parts = {}
    for name in set(names):
        parts[name] = ExactModel(machine).error(values) if name == "exact" else \
            truncated.error(values, 1 if name == "first" else 2)
    dp, dd = parts[names[0]]
    if len(names) == 2:
        dp2, dd2 = parts[names[1]]
        dp = [a - b for a, b in zip(dp, dp2)]
        dd = [a - b for a, b in zip(dd, dd2)] if dd is not None else None
    return dp, dd


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
    dp, dd = model_error(machine, v, model)
    return g1, g2, _component(dp, dd, component, 1.0 / UNITS[machine.length_unit].to_internal, G1.shape)


def _component(dp, dd, component, scale, shape):
    if component in ("dkx", "dky", "dkz"):
        if dd is None:
            raise ChaincompError("this machine has no tool direction: use dx, dy, dz or norm")
        return np.broadcast_to(np.asarray(dd["xyz".index(component[-1])], float), shape)
    if component == "norm":
        return np.sqrt(sum(np.broadcast_to(np.asarray(c, float), shape) ** 2 for c in dp)) * scale
    return np.broadcast_to(np.asarray(dp["xyz".index(component[-1])], float), shape) * scale


def _normalise(args) -> None:
    """One spelling for the options that have two, and the defaults that depend on the view."""
    if args.style and args.view and {"heatmap": "map"}.get(args.style, args.style) != args.view:
        raise ChaincompError(f"--style {args.style} and --view {args.view} disagree: give --view alone")
    args.view = args.view or {"heatmap": "map", "surface": "surface", None: "map"}[args.style]
    internal = {v: k for k, v in MODEL_NAMES.items()}
    args.model = "-".join(internal.get(m, m) for m in args.model.split("-"))
    if args.output is None and not args.html:
        args.output = "plot.png"
    if args.grid is None:
        args.grid = DEFAULT_GRID[args.view]
    elif args.view == "volume" and args.grid > MAX_VOLUME_GRID:
        raise ChaincompError(f"--grid {args.grid}: the volume view takes 2 to {MAX_VOLUME_GRID} points per axis")


def run(args) -> int:
    F.use_agg()
    _normalise(args)
    refuse_empty(("--params", args.params), ("--over", args.over), ("--range", args.range1),
                 ("--range2", args.range2), ("-o", args.output), ("--html", args.html))
    inputs = (args.machine, args.params, args.replay, args.table)
    check_image(args.output, *inputs)
    if args.html:
        check_output(args.html, *inputs, option="--html")
        if os.path.splitext(args.html)[1].lower() not in (".html", ".htm"):
            raise ChaincompError(f"--html {args.html}: the file name must end in .html")
        if args.replay or args.table or args.error:
            raise ChaincompError("--html draws the surface and the volume view of a machine: not with --replay "
                                 "or --table")
        if args.output and os.path.abspath(args.output) == os.path.abspath(args.html):
            raise ChaincompError(f"--html {args.html}: is also the -o output")
    if args.output:
        import matplotlib.pyplot as plt
        fig = build_figure(args)
        F.save(fig, args.output)
        plt.close(fig)
        print(f"plot: wrote {args.output}", file=sys.stderr)
    if args.html:
        write_html(args)
        print(f"plot: wrote {args.html}", file=sys.stderr)
    return 0


def build_figure(args):
    """The matplotlib figure of the options (after _normalise), not yet saved."""
    if args.replay:
        return _replay_figure(args)
    if args.table or args.error:
        return _table_figure(args)
    if not args.machine:
        raise ChaincompError("give a MACHINE.yaml (or --replay REPLAY.csv)")
    if args.view == "volume":
        return _volume_figure(volume_data(args, args.over, args.grid))
    return _map_figure(map_data(args, args.over, args.grid), surface=args.view == "surface")


@dataclass
class MapData:
    title: str
    a1: object          # the two axes drawn (symbols)
    a2: object
    g1: np.ndarray      # their values, declared units
    g2: np.ndarray
    z: np.ndarray       # the component on the grid [g1, g2], in `unit`
    label: str          # the component with its unit


def _machine_values(args):
    """(machine, values, whether any error is given), loaded once per run: the HTML file's two
    views share them, and their warnings are printed once."""
    if getattr(args, "loaded", None) is None:
        machine = load(args.machine)
        values, has_errors = values_for(machine, args.params, args.sets)
        args.loaded = machine, values, has_errors
    return args.loaded


def _warn_without_errors(args) -> None:
    """Once per run, after the view's options were checked (a bad option is then the one line)."""
    if not args.loaded[2] and not getattr(args, "warned_without_errors", False):
        F.warn("no error values (give --params P.yaml, or --set an error): every error is zero, so the "
               "figure shows nothing")
        args.warned_without_errors = True


def map_data(args, over_text: str | None, grid: int) -> MapData:
    """The map of args.component over two axes (over_text 'A1,A2', default the first two)."""
    machine, values, has_errors = _machine_values(args)
    names = [a.name for a in machine.axes]
    if len(names) < 2:
        raise ChaincompError(f"{machine.name} has one axis ({', '.join(names)}): a map, a surface and --html draw "
                             "over two; --view volume draws the error along one")
    over = tuple(n.strip() for n in over_text.split(",")) if over_text else tuple(names[:2])
    if len(over) != 2 or over[0] == over[1] or any(n not in names for n in over):
        raise ChaincompError(f"--over expects two different axes of {machine.name} ({', '.join(names)}), "
                             f"got {over_text!r}")
    a1, a2 = (machine.symbol(n) for n in over)
    r1 = _range(args.range1, "--range", a1) if args.range1 else a1.limits
    r2 = _range(args.range2, "--range2", a2) if args.range2 else (
        _range(args.range1, "--range", a2) if args.range1 else a2.limits)
    g1, g2, z = error_grid(machine, values, over, (r1, r2), grid, args.component, args.model)
    bad = np.argwhere(~np.isfinite(z))
    if len(bad):
        i, j = bad[0]
        raise ChaincompError(f"{args.component} is not finite at {over[0]} = {g1[i]:g}, {over[1]} = {g2[j]:g}: the "
                             "machine's expressions or the values given leave their domain there")
    _warn_without_errors(args)
    if has_errors and not np.any(z):
        F.warn(f"{args.component} is zero everywhere on this grid: no error given moves it, nothing to draw")
    factor, unit = F.component_unit(args.component, machine.length_unit, args.units)
    what = F.COMPONENT_TEXT[args.component]
    title = F.title(machine, f"{what} over {over[0]} and {over[1]}", args.params, args.sets, args.model,
                    F.held_text(machine, values, over))
    return MapData(title, machine.symbol(over[0]), machine.symbol(over[1]), g1, g2, z * factor,
                   F.label(what, unit))


def _map_figure(d: MapData, surface: bool):
    import matplotlib.pyplot as plt
    fig = plt.figure(figsize=(14, 6) if surface else (8, 6), dpi=100)
    ax = fig.add_subplot(1, 2 if surface else 1, 1)
    mesh = ax.pcolormesh(d.g1, d.g2, d.z.T, shading="auto", cmap="viridis")
    fig.colorbar(mesh, ax=ax, label=d.label)
    ax.set_xlabel(F.axis_label(d.a1))
    ax.set_ylabel(F.axis_label(d.a2))
    if surface:
        ax3 = fig.add_subplot(1, 2, 2, projection="3d")
        G1, G2 = np.meshgrid(d.g1, d.g2, indexing="ij")
        ax3.plot_surface(G1, G2, d.z, cmap="viridis", norm=mesh.norm, linewidth=0)
        ax3.set_xlabel(F.axis_label(d.a1))
        ax3.set_ylabel(F.axis_label(d.a2))
        ax3.set_zlabel(d.label)
    fig.suptitle(d.title, fontsize="medium")
    return fig


@dataclass
class VolumeData:
    title: str
    axes: list            # the grid axes (symbols)
    point: np.ndarray     # (n, 3) nominal tool points, the machine's length unit
    error: np.ndarray     # (n, 3) tool point errors, in `unit`
    unit: str
    length_unit: str
    scale: float          # drawn arrow length (length unit) per `unit` of error
    key: float            # the key arrow's length, in `unit`


def _volume_axes(machine, text: str | None) -> list[str]:
    names = [a.name for a in machine.axes]
    if not text:
        linear = [a.name for a in machine.axes if a.unit.kind == "length"]
        return (linear or names)[:3]
    pick = [n.strip() for n in text.split(",")]
    if not 1 <= len(pick) <= 3 or len(set(pick)) != len(pick) or any(n not in names for n in pick):
        raise ChaincompError(f"--over expects one to three different axes of {machine.name} ({', '.join(names)}) "
                             f"for the volume view, got {text!r}")
    return pick


def _points(axis, limits, grid: int) -> np.ndarray:
    """grid values of an axis across its limits; a rotary axis of a turn or more takes one turn
    without its end (-360 and 360 deg would draw the same arrows twice)."""
    lo, hi = limits
    if axis.unit.kind == "angle" and axis.to_internal(hi - lo) >= 2 * math.pi - 1e-12:
        return np.linspace(lo, lo + axis.from_internal(2 * math.pi), grid, endpoint=False)
    return np.linspace(lo, hi, grid)


def _nice(x: float) -> float:
    """1, 2 or 5 times a power of ten, at most x (x > 0)."""
    p = 10.0 ** math.floor(math.log10(x))
    return next(m * p for m in (5, 2, 1) if m * p <= x)


def volume_data(args, over_text: str | None, grid: int) -> VolumeData:
    """Tool points and errors on a grid of one to three axes (default: the linear axes)."""
    machine, values, has_errors = _machine_values(args)
    over = _volume_axes(machine, over_text)
    ranges = [machine.symbol(n).limits for n in over]
    if args.view == "volume" and args.range1:   # otherwise the ranges are the map's
        ranges[0] = _range(args.range1, "--range", machine.symbol(over[0]))
    if args.view == "volume" and args.range2 and len(over) > 1:
        ranges[1] = _range(args.range2, "--range2", machine.symbol(over[1]))
    grids = np.meshgrid(*(_points(machine.symbol(n), r, grid) for n, r in zip(over, ranges)), indexing="ij")
    v = dict(values)
    for n, g in zip(over, grids):
        v[n] = machine.symbol(n).to_internal(g.ravel())
    # errors at zero: the nominal pose (an error given as a table is an object, not a number)
    nominal = {k: (0.0 if machine.symbol(k).role == "error" else x) for k, x in v.items()}
    shape = grids[0].ravel().shape
    point, _ = ExactModel(machine).pose(nominal)
    dp, _ = model_error(machine, v, args.model)
    length = UNITS[machine.length_unit].to_internal
    point = np.stack([np.broadcast_to(np.asarray(c, float), shape) for c in point], axis=1) / length
    shown = display_unit("length", args.units)
    err = np.stack([np.broadcast_to(np.asarray(c, float), shape) for c in dp], axis=1) / shown.to_internal
    if not (np.isfinite(point).all() and np.isfinite(err).all()):
        raise ChaincompError("the tool point or its error is not finite on this grid: the machine's expressions "
                             "or the values given leave their domain there")
    biggest = float(np.linalg.norm(err, axis=1).max())
    _warn_without_errors(args)
    if has_errors and biggest == 0.0:
        F.warn("the tool point error is zero everywhere on this grid: nothing to draw")
    span = float((point.max(axis=0) - point.min(axis=0)).max()) or 1.0
    key = _nice(biggest) if biggest > 0 else 1.0
    scale = 0.15 * span / (biggest or 1.0)   # the longest arrow: 15 % of the travel
    held = F.held_text(machine, values, over)
    magnification = _round(scale * length / shown.to_internal)   # drawn length / error length
    title = F.title(machine, f"tool point error over {', '.join(over)} (arrows x {magnification})",
                    args.params, args.sets, args.model, held)
    return VolumeData(title, [machine.symbol(n) for n in over], point, err, shown.name, machine.length_unit,
                      scale, key)


def _round(x: float) -> str:
    return f"{float(f'{x:.2g}'):g}"


def _volume_figure(d: VolumeData):
    import matplotlib.pyplot as plt
    from matplotlib import cm, colors
    fig = plt.figure(figsize=(9, 8), dpi=100)
    ax = fig.add_subplot(projection="3d")
    size = np.linalg.norm(d.error, axis=1)
    lo_size, hi_size = float(size.min()), float(size.max())
    norm = colors.Normalize(lo_size, hi_size if hi_size > lo_size else lo_size + 1.0)
    rgba = cm.viridis(norm(size))
    u = d.error * d.scale
    # thick shafts and wide heads: thin ones vanished against the panes and grid at 5^3 arrows
    ax.quiver(*d.point.T, *u.T, colors=np.concatenate([rgba, rgba, rgba]), arrow_length_ratio=0.35,
              linewidths=2.2)
    ax.scatter(*d.point.T, s=10, color="black", depthshade=False, label="nominal tool point")
    x0, y0, z0 = _key_origin(d)
    ax.quiver(x0, y0, z0, d.key * d.scale, 0, 0, color="red", arrow_length_ratio=0.35, linewidths=2.5)
    # the key's words flat in a corner, clear of the arrows (a 3-D text lay over them or, at the
    # left, beyond the canvas, which does not count 3-D texts in its bounds)
    ax.text2D(0.0, 1.0, f"key: the red arrow (above the grid's corner) is {d.key:g} {d.unit}",
              transform=ax.transAxes, color="red", fontweight="bold", va="top")
    ax.xaxis.pane.set_alpha(0.3)
    ax.yaxis.pane.set_alpha(0.3)
    ax.zaxis.pane.set_alpha(0.3)
    for set_label, c in zip((ax.set_xlabel, ax.set_ylabel, ax.set_zlabel), "xyz"):
        set_label(F.label(f"tool point {c}", d.length_unit))
    fig.colorbar(cm.ScalarMappable(norm=norm, cmap="viridis"), ax=ax, shrink=0.6,
                 label=F.label("|tool point error|", d.unit))
    fig.suptitle(d.title, fontsize="medium")
    return fig


def _key_origin(d: VolumeData) -> tuple[float, float, float]:
    """Where the key arrow starts: above the grid's top left corner, clear of the field."""
    lo, hi = d.point.min(axis=0), d.point.max(axis=0)
    return float(lo[0]), float(lo[1]), float(hi[2] + 0.1 * (float((hi - lo).max()) or 1.0))


def write_html(args) -> None:
    """The surface (over the map's axes) and the volume view in one self-contained plotly file."""
    import plotly.graph_objects as go
    from plotly.subplots import make_subplots
    if not args.machine:
        raise ChaincompError("--html needs a MACHINE.yaml")
    # --over and --grid belong to the view asked for; the other view takes its defaults
    volume = args.view == "volume"
    m = map_data(args, None if volume else args.over, DEFAULT_GRID["map"] if volume else args.grid)
    v = volume_data(args, args.over if volume else None, args.grid if volume else DEFAULT_GRID["volume"])
    fig = make_subplots(rows=1, cols=2, specs=[[{"type": "scene"}, {"type": "scene"}]],
                        subplot_titles=tuple(_html_title(d.title) for d in (m, v)),
                        horizontal_spacing=0.08)
    label = html_text(m.label)   # plotly reads its texts as a subset of HTML
    fig.add_trace(go.Surface(x=m.g1, y=m.g2, z=m.z.T, colorscale="Viridis", name=label,
                             colorbar={"title": {"text": label}, "x": 0.43, "len": 0.8}), 1, 1)
    tips = v.point + v.error * v.scale
    xs, ys, zs = (np.column_stack([v.point[:, k], tips[:, k], np.full(len(tips), np.nan)]).ravel()
                  for k in range(3))
    size = np.linalg.norm(v.error, axis=1)
    # thick shafts in their size's colour and a dot at each tip: thin grey lines were hard to read
    lo, hi = float(size.min()), float(size.max())
    fig.add_trace(go.Scatter3d(x=xs, y=ys, z=zs, mode="lines", name="error (scaled)", hoverinfo="skip",
                               line={"color": np.repeat(size, 3), "colorscale": "Viridis", "cmin": lo,
                                     "cmax": hi, "width": 7}), 1, 2)
    fig.add_trace(go.Scatter3d(x=tips[:, 0], y=tips[:, 1], z=tips[:, 2], mode="markers",
                               marker={"size": 4, "color": size, "colorscale": "Viridis", "cmin": lo, "cmax": hi,
                                       "line": {"color": "black", "width": 1},
                                       "colorbar": {"title": {"text": F.label("|tool point error|", v.unit)},
                                                    "x": 0.93, "len": 0.8}},
                               text=[f"{s:.3f} {v.unit}" for s in size], name="arrow tips"), 1, 2)
    x0, y0, z0 = _key_origin(v)
    fig.add_trace(go.Scatter3d(x=[x0, x0 + v.key * v.scale], y=[y0, y0], z=[z0, z0],
                               mode="lines+text", line={"color": "red", "width": 6}, text=["", f"{v.key:g} {v.unit}"],
                               name=f"key: {v.key:g} {v.unit}"), 1, 2)
    fig.update_scenes(xaxis_title=F.axis_label(m.a1), yaxis_title=F.axis_label(m.a2), zaxis_title=label,
                      row=1, col=1)
    fig.update_scenes(**{f"{c}axis_title": F.label(f"tool point {c}", v.length_unit) for c in "xyz"}, row=1, col=2)
    # the page's width is the window's (no horizontal scroll at 1280 px); the titles in small
    # type, a line per part, so that each stays over its half; each colour bar beside its scene
    fig.update_annotations(font_size=12)
    for k, (a, b) in enumerate(((0.0, 0.42), (0.51, 0.92))):
        fig.layout[f"scene{k + 1 if k else ''}"].domain.x = (a, b)
        fig.layout.annotations[k].x = (a + b) / 2
    fig.update_layout(autosize=True, height=750, showlegend=True, margin={"t": 140, "l": 10, "r": 10},
                      legend={"orientation": "h", "x": 0.51, "y": 0.0, "yanchor": "top"})
    write_file(args.html, fig.to_html(include_plotlyjs=True, full_html=True, default_width="100%",
                                      default_height="750px", config={"responsive": True}))


def _html_title(title: str) -> str:
    """A figure's title for plotly (a subset of HTML): escaped, its second line a line per part."""
    first, _, rest = title.partition("\n")
    return "<br>".join(html_text(t) for t in [first, *rest.split("; ")] if t)


def _replay_figure(args):
    import matplotlib.pyplot as plt
    rows, cols = _read_replay_csv(args.replay)
    ok = cols.pop("ok")
    t = (cols["utime"] - cols["utime"][0]) * 1e-6
    axes = [c[len("commanded_"):] for c in cols if c.startswith("commanded_")]   # e.g. X_mm, Ap_deg
    linear = [a for a in axes if a.endswith("_mm")]
    rotary = [a for a in axes if not a.endswith("_mm")]
    machine = load(args.machine) if args.machine else None
    predicted = _predicted(args, machine, axes, cols)
    if predicted:
        errors = predicted
        source = "the exact model at the corrected axes (ramp included)"
        compensated = _compensated_with(args, predicted["with"][0], cols["residual_point_mm"])
    else:   # the compensator's own residuals
        direction = cols.get("residual_direction_rad")
        errors = {"with": (cols["residual_point_mm"], direction if direction is not None and direction.any()
                           else None)}
        source = "the compensator's residual (ramp included)"
        compensated = "compensated with values the CSV does not name"
    um, arcsec = display_unit("length", args.units), display_unit("angle", args.units)
    panels = [("commanded", linear, "mm", 1.0), ("commanded", rotary, "deg", 1.0),
              ("correction", linear, um.name, 1.0 / um.to_internal),
              ("correction", rotary, arcsec.name, UNITS["deg"].to_internal / arcsec.to_internal)]
    panels = [p for p in panels if p[1]]
    has_direction = errors["with"][1] is not None
    n = len(panels) + 1 + has_direction
    fig, grid = plt.subplots(n, 1, figsize=(10, 2.1 * n + 1.2), dpi=100, sharex=True, squeeze=False)
    grid = grid[:, 0]
    for ax, (what, names, unit, k) in zip(grid, panels):
        for a in names:
            ax.plot(t, cols[f"{what}_{a}"] * k, label=a.rsplit("_", 1)[0])
        ax.set_ylabel(F.label(what, unit))
        ax.legend(loc="upper right", fontsize="small", ncol=len(names))
    for k, (quantity, unit) in enumerate([("|tool point error|", um)] + ([("tool axis error", arcsec)]
                                                                        if has_direction else [])):
        ax = grid[len(panels) + k]
        if "without" in errors:
            ax.plot(t, errors["without"][k] / unit.to_internal, label="without compensation", color="C3")
        with_ = errors["with"][k] / unit.to_internal
        ax.plot(t, with_, label=f"with compensation (median {np.median(with_):.2g} {unit.name})", color="C2")
        ax.set_ylabel(F.label(quantity, unit.name))
        ax.legend(loc="upper right", fontsize="small")
    grid[-1].set_xlabel(F.label("time", "s"))
    what = f"replay of {os.path.basename(args.replay)}, {ok} corrected, {rows - ok} rejected, {compensated}"
    title = F.title(machine or "(no machine file)", what, args.params, args.sets, "exact",
                    extra=f"with compensation: {source}")
    fig.suptitle("\n".join(F.lines(line, 110) for line in title.split("\n")), fontsize="medium")
    fig.tight_layout()
    return fig


AGREE_MM = 1e-6   # the compensator's residual and the exact model's, both double precision: within 1 nm


def _compensated_with(args, model_residual: np.ndarray, replay_residual: np.ndarray) -> str:
    """Which values the replay compensated with, for the title: a replay CSV does not name its
    params, but its residual column is the compensator's own (mm); where the exact model with
    --params at the corrected axes gives the same residual on every record, they were these."""
    given = F.values_text(args.params, args.sets)
    worst = float(np.max(np.abs(model_residual - replay_residual)))
    if worst <= AGREE_MM:
        return f"compensated with {given}"
    F.warn(f"{args.replay}: its residuals differ from the exact model's with {given} by up to {worst * 1e3:.3g} µm: "
           "the replay compensated with other values (another params file, updates or a thermal model in the log)")
    return f"compensated with values other than {given} (residuals differ by up to {worst * 1e3:.3g} µm)"


def _predicted(args, machine, axes: list[str], cols: dict):
    """{"without": (|point error|, axis angle or None), "with": (...)}, internal units, per record:
    the exact model's tool pose at the commanded and at the corrected axes, each against the
    nominal pose at the commanded axes. None without a machine and error values."""
    if not (machine and (args.params or args.sets)):
        F.warn("the tool error without compensation needs MACHINE.yaml and --params: only the error with "
               "compensation is drawn")
        return None
    values, _ = values_for(machine, args.params, args.sets)
    have = [a.rsplit("_", 1)[0] for a in axes]
    if have != [a.name for a in machine.axes]:
        raise ChaincompError(f"the CSV's axes ({', '.join(have)}) are not those of {machine.name} "
                             f"({', '.join(a.name for a in machine.axes)})", args.replay, 1)
    missing = [a for a in axes if "corrected_" + a not in cols]
    if missing:
        raise ChaincompError(f"no corrected_{missing[0]} column: the error with compensation needs the corrected "
                             "axes", args.replay, 1)
    exact = ExactModel(machine)
    shape = cols["utime"].shape

    def pose(prefix: str, with_errors: bool):
        v = dict(values)
        for a in axes:
            name, unit = a.rsplit("_", 1)
            v[name] = cols[prefix + a] * UNITS[unit].to_internal
        if not with_errors:
            v.update({s.name: 0.0 for s in machine.errors})
        p, d = exact.pose(v)
        stack = lambda c: np.stack([np.broadcast_to(np.asarray(x, float), shape) for x in c], axis=1)  # noqa: E731
        return stack(p), (stack(d) if d is not None else None)

    p0, d0 = pose("commanded_", False)
    out = {}
    for key, prefix in (("without", "commanded_"), ("with", "corrected_")):
        p, d = pose(prefix, True)
        out[key] = (np.linalg.norm(p - p0, axis=1), angle_between(d0, d) if d0 is not None else None)
    return out


def _read_replay_csv(path: str) -> tuple[int, dict[str, np.ndarray]]:
    """(rows, {"ok": count, column: values of the corrected records}) of a replay CSV: utime,
    residual_point_mm, residual_direction_rad (where there) and every commanded_/correction_ column
    (named AXIS_mm or AXIS_deg, the wire's units), each cell a finite number."""
    def fail(message: str, line: int | None = None, field: str | None = None):
        raise ChaincompError(message, path, line, field)

    table = csvtable.read(path, max_rows=MAX_REPLAY_ROWS, max_bytes=MAX_REPLAY_BYTES)
    names = table.header
    wanted = ["utime", "residual_point_mm"] + [c for c in names if c == "residual_direction_rad"
                                                or c.startswith(("commanded_", "corrected_", "correction_"))]
    missing = [c for c in ("result", "utime", "residual_point_mm") if c not in names]
    if missing or not any(c.startswith("commanded_") for c in names):
        fail(f"not a 'chaincomp replay' CSV: no {(missing or ['commanded_*'])[0]} column", table.line)
    for c in wanted:
        if c.startswith(("commanded_", "corrected_", "correction_")) and not c.endswith(("_mm", "_deg")):
            fail(f"column {c}: an axis column ends in _mm or _deg (the units on the wire)", table.line)
    column = {c: k for k, c in enumerate(names)}
    out: dict[str, list[float]] = {c: [] for c in wanted}
    back, rows = None, 0
    for row in table.rows:
        rows += 1
        if row.cells[column["result"]] != "ok":
            continue
        for c in wanted:
            v = table.number(row, column[c])
            if c == "utime" and not (0 <= v <= MAX_UTIME and v == int(v)):
                fail(f"expected whole microseconds from 0 to 2^62, got {row.cells[column[c]]!r}", row.line, c)
            elif c != "utime" and not abs(v) <= MAX_LITERAL:
                fail(f"{row.cells[column[c]]!r} is beyond {MAX_LITERAL:g} in magnitude", row.line, c)
            out[c].append(v)
        if back is None and len(out["utime"]) > 1 and out["utime"][-1] < out["utime"][-2]:
            back = row.line
    if not out["utime"]:
        fail("no corrected records to plot (is it a 'chaincomp replay' CSV?)")
    if back is not None:
        F.warn(f"{path}:{back}: utime goes back: the records are drawn in the file's order, not sorted")
    cols = {c: np.array(v) for c, v in out.items()}
    cols["ok"] = len(out["utime"])
    return rows, cols


def _table_figure(args):
    """Points, interpolant and slope of one varying error, 5 % past both ends."""
    import matplotlib.pyplot as plt
    from ..model.varying import Table, parse_varying
    from ..model.yamlsource import load_yaml
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
        from ..model.params import load_params
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
    outside = f"shaded: outside the {'table' if isinstance(v, Table) else 'range'}"
    fig.suptitle(F.title(machine or "(no machine file)", f"{args.error}: {v.describe()}",
                         args.table, extra=outside), fontsize="medium")
    fig.tight_layout()
    return fig
