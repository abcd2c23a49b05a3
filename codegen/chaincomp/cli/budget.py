"""``chaincomp budget``: the error budget of a machine over its working volume."""

from __future__ import annotations

import os
import sys

import numpy as np

from ..analysis import budget as B
from ..analysis.tolerances import from_params, load_tolerances
from ..errors import ChaincompError
from ..model.display import add_units_argument
from . import figures as F
from .common import (add_format_argument, add_machine_argument, add_model_argument, add_seed_argument,
                     add_values_arguments, check_finite, check_image, integer, load, to_json, values_for)

MAX_SAMPLES = 2_000_000


def add_parser(sub) -> None:
    p = sub.add_parser("budget", help="error budget over the working volume: worst case, RSS, Monte Carlo",
                       description="Error budget of the tool error over a grid of the machine's axes (limits "
                                   "from the machine file): per component the worst case (sum of "
                                   "|gain x bound|), the RSS and standard deviation of independent errors "
                                   "(uniform or normal, from the tolerance file), a seeded Monte Carlo of the "
                                   "exact model at the worst point, the dominant contributors there, and the "
                                   "largest |gain| of every error over the grid. Without --tolerances the "
                                   "error values of --params are read as bounds (uniform on +-|value|); an "
                                   "error given as a table (or polynomial) is bounded by its largest |value| on "
                                   "the grid, unless the tolerance file bounds it. A component that no error "
                                   "moves is reported as identically zero.")
    add_machine_argument(p)
    add_values_arguments(p)
    p.add_argument("--tolerances", metavar="T.yaml", help="bounds and distributions (configs/tolerances/*.yaml)")
    p.add_argument("--over", metavar="A1,A2,...", help="axes of the grid (default: every axis); the others "
                   "stay at 0 (or mid-range), or --set")
    p.add_argument("--grid", type=integer(2, B.MAX_POINTS), default=9, metavar="N",
                   help=f"points per grid axis, limits included (default 9; at most {B.MAX_POINTS} points and "
                        f"{B.MAX_POINT_ERRORS} points x errors in all)")
    add_model_argument(p, B.ORDERS, what="model of the gains")
    p.add_argument("--samples", type=integer(0, MAX_SAMPLES), default=10000, metavar="N",
                   help=f"Monte Carlo samples of the exact model at each worst point (default 10000; 0: none; "
                        f"at most {MAX_SAMPLES})")
    add_seed_argument(p, "Monte Carlo seed")
    add_format_argument(p)
    add_units_argument(p)
    p.add_argument("--top", type=integer(0, 10**6), default=5, metavar="N",
                   help="contributors listed per component in text (default 5; 0: all)")
    p.add_argument("--plot", metavar="OUT.png", help="also write worst-case and RSS maps and a bar chart of "
                   "the contributions")
    p.add_argument("--map", metavar="A1,A2", help="the two grid axes of the maps (default: the first two)")
    p.add_argument("--component", choices=B.POSITION + B.DIRECTION + B.ORIENTATION,
                   help="component of the plot: dx, dy, dz; dkx, dky, dkz (tool direction); wx, wy, wz "
                        "(a tool frame's rotation vector); default: the position component with the largest "
                        "worst case")
    p.set_defaults(run=run)


def run(args) -> int:
    check_image(args.plot, args.machine, args.params, args.tolerances, option="--plot")
    machine = load(args.machine)
    over = [n.strip() for n in args.over.split(",")] if args.over else None
    set_names = {item.partition("=")[0].strip() for item in args.sets}
    values, _ = values_for(machine, args.params, args.sets)
    grid_names = over or [a.name for a in machine.axes]
    clash = [n for n in grid_names if n in set_names]
    if clash:
        raise ChaincompError(f"--set {clash[0]}: {clash[0]} is an axis of the grid; leave it out of --over "
                             f"to hold it at a value")
    grid = B.make_grid(machine, over, args.grid, values)
    # a table (or polynomial) in --params: its largest |value| on the grid is its bound
    tables = B.table_bounds(values, grid)
    if args.tolerances:
        values, tol = B.with_tables(values, load_tolerances(args.tolerances, machine), tables, machine)
        centred = True
    else:
        tol = from_params({**values, **tables}, machine)
        values, _ = B.with_tables(values, None, tables, machine)
        centred = False
        if not tol.items:
            raise ChaincompError("nothing to budget: give --tolerances T.yaml, or error values in --params")
    pick = _map_axes(grid, args.map)   # the plot's choices checked before the work
    if args.component and args.component not in B.components(machine):
        missing = "tool frame (tool.reference or tool.rotation)" if args.component in B.ORIENTATION else "tool direction"
        raise ChaincompError(f"--component {args.component}: this machine has no {missing}")
    b = B.compute(machine, values, tol, grid, order=args.model, samples=args.samples, seed=args.seed,
                  centre_on_params=centred, tables=tables)
    doc = B.to_json(b)
    check_finite(doc)
    print(to_json(doc) if args.format == "json" else B.to_text(b, args.top, args.units))
    if args.plot:
        plot(b, args.plot, pick, args.component, args.params, args.sets, args.tolerances)
        print(f"budget: wrote {args.plot}", file=sys.stderr)
    return 0


def _map_axes(grid: B.Grid, text: str | None) -> list[str]:
    """The two grid axes of the maps (--map), or the first two (one on a grid of one axis)."""
    names = [a.name for a in grid.axes]
    if not text:
        return names[:2]
    pick = [n.strip() for n in text.split(",")]
    if len(pick) != 2 or pick[0] == pick[1] or any(n not in names for n in pick):
        raise ChaincompError(f"--map expects two different axes of the grid ({', '.join(names)}), got {text!r}")
    return pick


def plot(b: B.Budget, output: str, pick: list[str], component: str | None, params: str | None = None,
         sets=(), tolerances: str | None = None) -> None:
    F.use_agg()
    import matplotlib.pyplot as plt
    fig = build_plot(b, pick, component, params, sets, tolerances)
    F.save(fig, output)
    plt.close(fig)


def build_plot(b: B.Budget, pick: list[str], component: str | None, params: str | None = None, sets=(),
               tolerances: str | None = None):
    """Worst-case and RSS maps over two grid axes (the largest value over the other grid axes,
    each map its own colour scale: the RSS is a fraction of the worst case) and a bar chart of
    the contributions at the worst point; the figure, not saved."""
    import matplotlib.pyplot as plt

    names = [a.name for a in b.grid.axes]
    if component is None:
        component = max(B.POSITION, key=lambda c: float(b.components[c].worst.max()))
    cb = b.components[component]
    scale, unit = B._display(b, component)
    two = len(pick) == 2
    fig = plt.figure(figsize=(16 if two else 11, 5.2), dpi=100)
    panels = 3 if two else 2
    if two:
        i1, i2 = names.index(pick[0]), names.index(pick[1])
        rest = tuple(k for k in range(len(names)) if k not in (i1, i2))
        maps = []
        for arr in (cb.worst, cb.rss):
            env = np.max(arr, axis=rest) if rest else np.asarray(arr)
            maps.append(env if i1 < i2 else env.T)   # -> [axis 1, axis 2]
        a1, a2 = b.grid.axes[i1], b.grid.axes[i2]
        others = ", ".join(names[k] for k in rest)
        for p, (title, mp) in enumerate(zip(("worst case", "RSS"), maps), 1):
            ax = fig.add_subplot(1, panels, p)
            mesh = ax.pcolormesh(b.grid.points[i1], b.grid.points[i2], mp.T * scale, shading="auto",
                                 cmap="viridis")
            fig.colorbar(mesh, ax=ax, label=F.label(f"{title} {component}", unit))
            ax.set_xlabel(F.axis_label(a1))
            ax.set_ylabel(F.axis_label(a2))
            ax.set_title(f"{title}" + (f" (largest over {others})" if others else ""), fontsize="medium")
    else:
        i1 = names.index(pick[0])
        rest = tuple(k for k in range(len(names)) if k != i1)
        ax = fig.add_subplot(1, panels, 1)
        x = b.grid.points[i1]
        for label, arr in (("worst case", cb.worst), ("RSS", cb.rss), ("sigma", cb.sigma)):
            ax.plot(x, (np.max(arr, axis=rest) if rest else arr) * scale, label=label)
        ax.set_xlabel(F.axis_label(b.grid.axes[i1]))
        ax.set_ylabel(F.label(component, unit))
        ax.legend()
    ax = fig.add_subplot(1, panels, panels)
    rows = B.contributors(b, component)[:15]
    if rows:
        labels = [r["error"] for r in rows][::-1]
        vals = [r["contribution"] * scale for r in rows][::-1]
        bars = ax.barh(labels, vals, color="tab:blue")
        for bar, r in zip(bars, rows[::-1]):
            ax.text(bar.get_width(), bar.get_y() + bar.get_height() / 2, f" {100 * r['share_worst']:.1f} %",
                    va="center", fontsize="small")
        ax.set_xlim(0, max(vals) * 1.25 or 1.0)
    ax.set_xlabel(F.label("|gain| x bound", unit))
    ax.set_ylabel("error source")
    at = ", ".join(f"{n} = {v:g} {b.machine.symbol(n).unit.name}"
                   for n, v in B._axes_at(b, cb.worst_index).items())
    ax.set_title("contributions at the worst point\n" + F.lines(f"({at})", 48), fontsize="medium")
    held = ", ".join(f"{n} = {v:g} {b.machine.symbol(n).unit.name}" for n, v in b.grid.fixed.items())
    tol = f"tolerances {os.path.basename(tolerances)}" if tolerances else "--params values as bounds"
    fig.suptitle(F.title(b.machine, f"budget of {component}; worst {float(cb.worst.max()) * scale:.3g} {unit}, "
                         f"RSS there {float(cb.rss[cb.worst_index]) * scale:.3g} {unit}", params, sets, b.order,
                         held, tol), fontsize="medium")
    fig.tight_layout()
    return fig
