"""``chaincomp iso230-2``: the ISO 230-2:2014 evaluation of one axis from a CSV of laser runs."""

from __future__ import annotations

import sys
import unicodedata

from ..measure import iso230_2 as iso
from . import figures as F
from .common import add_format_argument, check_image, to_json

# name in the JSON, label in the text report (the standard's symbols)
AXIS_FIGURES = [
    ("B", "B   reversal error of the axis, max |B_i|"),
    ("B_mean", "B̄   mean reversal error, mean B_i"),
    ("E_up", "E↑  systematic positioning error, unidirectional ↑"),
    ("E_down", "E↓  systematic positioning error, unidirectional ↓"),
    ("E", "E   systematic positioning error, bidirectional"),
    ("M", "M   mean bidirectional positioning error range"),
    ("R_up", "R↑  repeatability, unidirectional ↑, max R_i↑"),
    ("R_down", "R↓  repeatability, unidirectional ↓, max R_i↓"),
    ("R", "R   repeatability, bidirectional, max R_i"),
    ("A_up", "A↑  accuracy, unidirectional ↑"),
    ("A_down", "A↓  accuracy, unidirectional ↓"),
    ("A", "A   accuracy, bidirectional"),
]
PER_TARGET = [("mean_up", "x̄↑"), ("mean_down", "x̄↓"), ("mean", "x̄"), ("reversal", "B_i"), ("s_up", "s↑"),
              ("s_down", "s↓"), ("R_up", "R_i↑"), ("R_down", "R_i↓"), ("R_i", "R_i")]


def add_columns_arguments(p) -> None:
    """The CSV options shared with laser-to-params."""
    p.add_argument("runs", metavar="RUNS.csv", help="laser readings: target, run, direction, deviation or actual "
                   "(see docs/reference/formats.md)")
    p.add_argument("--columns", metavar="MAP", help="header names of another program's export, e.g. "
                   "'target=Target Position,actual=Measured,run=Run,direction=Dir' (fields: "
                   f"{', '.join(iso.FIELDS)})")
    p.add_argument("--column-units", metavar="POS,DEV", help="units of the target (and actual) and deviation columns "
                   "when the header has none, e.g. mm,um")


def read(args) -> iso.Runs:
    return iso.read_runs(args.runs, iso.parse_column_map(args.columns), iso.parse_units(args.column_units))


def add_parser(sub) -> None:
    p = sub.add_parser("iso230-2", help="ISO 230-2 evaluation of one axis from bidirectional laser runs",
                       description="Evaluate the positioning accuracy and repeatability of one axis as ISO "
                                   "230-2:2014 defines them, from n >= 2 bidirectional runs over m >= 2 "
                                   "target positions: per target the mean unidirectional and bidirectional "
                                   "deviations, reversal, standard uncertainties and repeatabilities; for the "
                                   "axis B, B̄, E↑, E↓, E, M, R↑, R↓, R, A↑, A↓, A. Deviations are reported "
                                   "in µm (angles in arcsec).")
    add_columns_arguments(p)
    add_format_argument(p, what="report format")
    p.add_argument("--plot", metavar="OUT.png", help="also draw the standard's plot: mean deviations per "
                   "direction with their ±2s bands over the target positions")
    p.set_defaults(run=run)


def report_doc(runs: iso.Runs, ev: iso.Evaluation) -> dict:
    return {
        "file": runs.file,
        "standard": "ISO 230-2:2014",
        "runs": len(runs.runs),
        "targets": len(runs.targets),
        "units": {"position": runs.position_unit.name, "deviation": runs.unit.name},
        "positions": [{"target": float(t), **{k: float(getattr(ev, k)[i]) for k, _ in PER_TARGET}}
                      for i, t in enumerate(runs.targets)],
        "axis": ev.axis,
    }


def _pad(text: str, width: int, right: bool = False) -> str:
    """Pad to a width on screen: the bar of x̄ and B̄ is a combining character of no width."""
    fill = " " * max(0, width - sum(not unicodedata.combining(c) for c in text))
    return fill + text if right else text + fill


def _text(runs: iso.Runs, ev: iso.Evaluation) -> str:
    u, pu = runs.unit.name, runs.position_unit.name
    out = [f"ISO 230-2:2014 evaluation of {runs.file}: {len(runs.targets)} targets, {len(runs.runs)} runs "
           f"each direction; deviations in {u}",
           "", f"{'P_i [' + pu + ']':>12}" + "".join(_pad(label, 9, True) for _, label in PER_TARGET)]
    for i, t in enumerate(runs.targets):
        out.append(f"{t:12.6g}" + "".join(f"{getattr(ev, k)[i]:9.3f}" for k, _ in PER_TARGET))
    out.append("")
    out += [f"  {_pad(label, 52)} {ev.axis[k]:9.3f} {u}" for k, label in AXIS_FIGURES]
    # the signed mean, not B = max |B_i| >= 0: ordinary lost motion has B_i < 0, and a
    # positive value in the table's reversal would double it
    out += ["", f"  to take the reversal out in a LinuxCNC table: chaincomp export --controller linuxcnc-comp "
                f"--mean-reversal AXIS={round(ev.axis['B_mean'], 3) + 0.0:.3f}{u} (B̄, signed)"]   # (never -0)
    return "\n".join(out)


def plot(runs: iso.Runs, ev: iso.Evaluation, output: str) -> None:
    F.use_agg()
    import matplotlib.pyplot as plt
    t = runs.targets
    fig, ax = plt.subplots(figsize=(9, 5.5))
    for mean, s, x, colour, label in ((ev.mean_up, ev.s_up, runs.up, "tab:blue", "↑"),
                                      (ev.mean_down, ev.s_down, runs.down, "tab:red", "↓")):
        ax.plot(t, mean, "-o", color=colour, ms=3, label=f"x̄_i{label}")
        ax.plot(t, mean + 2 * s, "--", color=colour, lw=0.8, label=f"x̄_i{label} ± 2 s_i{label}")
        ax.plot(t, mean - 2 * s, "--", color=colour, lw=0.8)
        for j in range(x.shape[1]):
            ax.plot(t, x[:, j], ".", color=colour, ms=2, alpha=0.5)
    ax.plot(t, ev.mean, ":", color="k", label="x̄_i (bidirectional)")
    a = ev.axis
    u = runs.unit.name
    ax.set_title(f"ISO 230-2: {runs.file} ({len(runs.runs)} runs)\n"
                 f"A = {a['A']:.2f}  E = {a['E']:.2f}  M = {a['M']:.2f}  R = {a['R']:.2f}  B = {a['B']:.2f} {u}",
                 fontsize=10)
    ax.set_xlabel(f"target position P_i [{runs.position_unit.name}]")
    ax.set_ylabel(f"deviation [{u}]")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    F.save(fig, output)
    plt.close(fig)


def run(args) -> int:
    check_image(args.plot, args.runs, option="--plot")
    runs = read(args)
    ev = iso.evaluate(runs)
    doc = report_doc(runs, ev)
    print(to_json(doc) if args.format == "json" else _text(runs, ev))
    if args.plot:
        plot(runs, ev, args.plot)
        print(f"iso230-2: plot -> {args.plot}", file=sys.stderr)
    return 0
