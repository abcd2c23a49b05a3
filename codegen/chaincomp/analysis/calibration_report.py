"""A calibration report a person reads and hands over: one self-contained HTML file (inline CSS,
inline SVG figures, no script, nothing fetched) of a fit of a machine's errors.

Any fitting verb fills one ``Calibration`` (plain numbers and text, already in the units to
show) and calls ``write_report``; the report knows nothing of how the fit was done. Today
``chaincomp identify --report`` fills it (cli/identify.py, ``calibration_of``); a probing fit
fills the same fields:

- ``setup``: what was measured and how, as (item, value) lines (files, probe, sphere, sigma);
- ``plan``: the measured positions, one row per pose (column names, rows of cells);
- ``residuals``: per pose, the size of the residual before the fit (every error at its
  starting value) and after it, in ``residual_unit``;
- ``dispersion``: per axis, KinematicsOpt's "measured" and "optimised" dispersion (a probing
  fit: per rotary axis; identify: per measured coordinate), its meaning in ``dispersion_meaning``;
- ``values``: each identified value with its standard uncertainty and unit, ``correlation``
  their correlation matrix in that order (or None);
- ``not_seen``: (name, why) of every error the data could not give a value;
- ``summary``: the fit's figures of merit as (item, value) lines; ``warnings``: what to act on.

Every text from outside (file names, reasons, labels) goes through escape.html_text; the
figures are drawn by matplotlib as SVG with their text as paths (no markup from a label)."""

from __future__ import annotations

import io
import math
from dataclasses import dataclass, field

from ..escape import html_text as _h
from ..output import write_file

MAX_TABLE_ROWS = 200   # poses listed in the residual table; beyond, the largest after the fit
OPEN_ROWS = 25         # a longer table is folded (a click opens it): the figures come first to the eye


@dataclass
class Value:
    name: str
    value: float
    uncertainty: float      # standard uncertainty, same unit
    unit: str               # e.g. µm, arcsec, µm/m


@dataclass
class Residual:
    label: str              # the pose: 'line 12', 'pose 3 (B = 45 deg, C = 90 deg)'
    before: float           # size of the residual before the fit, residual_unit (nan: not measured)
    after: float


@dataclass
class Dispersion:
    axis: str
    before: float
    after: float


@dataclass
class Calibration:
    verb: str                                   # 'chaincomp identify'
    machine: str
    date: str                                   # ISO 8601, UTC
    setup: list[tuple[str, str]] = field(default_factory=list)
    plan_columns: list[str] = field(default_factory=list)
    plan: list[list[str]] = field(default_factory=list)
    residual_unit: str = "µm"
    residuals: list[Residual] = field(default_factory=list)
    dispersion_meaning: str = ""
    dispersion: list[Dispersion] = field(default_factory=list)
    values: list[Value] = field(default_factory=list)
    correlation: list[list[float]] | None = None
    not_seen: list[tuple[str, str]] = field(default_factory=list)
    summary: list[tuple[str, str]] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)


_CSS = """
body{font:15px/1.45 system-ui,sans-serif;margin:0 auto;padding:16px 24px;max-width:1180px;color:#222}
h1{font-size:1.5em;margin:.2em 0}h2{font-size:1.2em;margin:1.4em 0 .4em;border-bottom:1px solid #ccc}
table{border-collapse:collapse;margin:.4em 0;max-width:100%}td,th{padding:2px 10px;border-bottom:1px solid #e4e4e4;
text-align:left;vertical-align:top}td.n{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}
.wide{overflow-x:auto;max-width:100%}figure{margin:.6em 0}figure svg{max-width:100%;height:auto}
figcaption{font-size:.9em;color:#555}.warn{background:#fff3cd;border-left:4px solid #e0a800;padding:6px 10px}
.ok{color:#1a7f37}.bad{color:#b42318}
"""


def write_report(path: str, c: Calibration) -> None:
    write_file(path, to_html(c))


def to_html(c: Calibration) -> str:
    out = ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
           '<meta name="viewport" content="width=device-width, initial-scale=1">',
           f"<title>{_h(f'Calibration of {c.machine}')}</title><style>{_CSS}</style></head><body>",
           f"<h1>Calibration of {_h(c.machine)}</h1>",
           f"<p>{_h(c.verb)}, {_h(c.date)}</p>"]
    out += [f'<p class="warn">{_h(w)}</p>' for w in c.warnings]
    out += ["<h2>Summary</h2>", _pairs(c.summary + _headline(c))]
    out += ["<h2>Set-up</h2>", _pairs(c.setup)]
    if c.plan:
        out += [f"<h2>Plan: {len(c.plan)} poses</h2>",
                _folded(_table(c.plan_columns, c.plan, numeric=range(1, len(c.plan_columns))), len(c.plan))]
    out += _residual_section(c)
    if c.dispersion:
        out += ["<h2>Dispersion per axis</h2>", f"<p>{_h(c.dispersion_meaning)}</p>",
                _table(["axis", f"before [{c.residual_unit}]", f"after [{c.residual_unit}]"],
                       [[d.axis, _num(d.before), _num(d.after)] for d in c.dispersion], numeric=(1, 2)),
                _figure(_dispersion_figure(c), "Dispersion per axis before and after the fit.")]
    out += _values_section(c)
    out += ["<h2>What these measurements could not see</h2>"]
    out += ([_table(["error", "why"], [list(r) for r in c.not_seen])] if c.not_seen
            else ["<p>Nothing: every error fitted was given a value.</p>"])
    out.append("</body></html>")
    return "\n".join(out) + "\n"


def _headline(c: Calibration) -> list[tuple[str, str]]:
    """The before/after in one line a manager reads first."""
    pairs = [(r.before, r.after) for r in c.residuals if math.isfinite(r.before) and math.isfinite(r.after)]
    if not pairs:
        return []
    before, after = max(b for b, _ in pairs), max(a for _, a in pairs)
    change = f" ({100 * after / before:.3g} % of before)" if before > 0 else ""
    return [("largest residual before / after the fit",
             f"{_num(before)} / {_num(after)} {c.residual_unit}{change}")]


def _residual_section(c: Calibration) -> list[str]:
    if not c.residuals:
        return []
    rows = c.residuals
    note = ""
    if len(rows) > MAX_TABLE_ROWS:
        rows = sorted(rows, key=lambda r: -r.after if math.isfinite(r.after) else 0.0)[:MAX_TABLE_ROWS]
        note = f"<p>The {MAX_TABLE_ROWS} poses with the largest residual after the fit, of {len(c.residuals)}.</p>"
    return ["<h2>Residual per measurement</h2>",
            _figure(_residual_figure(c), f"Size of each pose's residual (measured minus model) before the fit "
                                         f"and after it, {c.residual_unit}."),
            note, _folded(_table(["pose", f"before [{c.residual_unit}]", f"after [{c.residual_unit}]"],
                                 [[r.label, _num(r.before), _num(r.after)] for r in rows], numeric=(1, 2)), len(rows))]


def _values_section(c: Calibration) -> list[str]:
    out = ["<h2>Identified values</h2>"]
    if not c.values:
        return out + ["<p>None.</p>"]
    out.append(_table(["error", "value", "standard uncertainty", "unit", "value / uncertainty"],
                      [[v.name, _num(v.value), _num(v.uncertainty), v.unit,
                        _num(abs(v.value) / v.uncertainty) if v.uncertainty > 0 else "–"] for v in c.values],
                      numeric=(1, 2, 4)))
    out.append(_figure(_values_figure(c), "Each identified value with its 95 % interval (±2 standard "
                                          "uncertainties); an interval across zero: not told from no error."))
    if c.correlation is not None and len(c.values) > 1:
        names = [v.name for v in c.values]
        high = [(names[i], names[j], c.correlation[i][j]) for i in range(len(names)) for j in range(i + 1, len(names))
                if abs(c.correlation[i][j]) > 0.9]
        out.append("<h2>Correlations</h2>")
        out.append("<p>" + (_h("Above 0.9: " + ", ".join(f"{a}/{b} {r:+.3f}" for a, b, r in high)
                                + " (these values are not told apart well by these poses).") if high
                            else "None above 0.9 in magnitude.") + "</p>")
        out.append(_figure(_correlation_figure(c), "Correlation of the identified values (−1 to 1)."))
    return out


def _num(x: float) -> str:
    return "–" if not math.isfinite(x) else f"{x:.4g}"


def _folded(table: str, rows: int) -> str:
    """A table in a box that scrolls sideways if it must; folded when it is long."""
    inner = f'<div class="wide">{table}</div>'
    return inner if rows <= OPEN_ROWS else f"<details><summary>the {rows} rows</summary>{inner}</details>"


def _pairs(rows) -> str:
    return "<table>" + "".join(f"<tr><th>{_h(k)}</th><td>{_h(v)}</td></tr>" for k, v in rows) + "</table>"


def _table(columns, rows, numeric=()) -> str:
    numeric = set(numeric)
    head = "".join(f"<th>{_h(c)}</th>" for c in columns)
    body = "".join("<tr>" + "".join(f'<td{" class=n" if k in numeric else ""}>{_h(x)}</td>'
                                    for k, x in enumerate(row)) + "</tr>" for row in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


# ----------------------------------------------------------------------------- figures

def _figure(fig, caption: str) -> str:
    """A matplotlib figure as inline SVG (text drawn as paths: no font needed, no markup)."""
    import matplotlib.pyplot as plt
    buffer = io.StringIO()
    fig.savefig(buffer, format="svg", bbox_inches="tight", metadata={"Date": None})
    plt.close(fig)
    svg = buffer.getvalue()
    svg = svg[svg.index("<svg"):]          # no XML declaration or DOCTYPE inside HTML
    return f"<figure>{svg}<figcaption>{_h(caption)}</figcaption></figure>"


def _pyplot():
    import matplotlib
    matplotlib.use("Agg")
    matplotlib.rcParams["text.parse_math"] = False   # a $ in a label is a dollar
    matplotlib.rcParams["svg.fonttype"] = "path"
    import matplotlib.pyplot as plt
    return plt


def _residual_figure(c: Calibration):
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(10, 3.6), dpi=100)
    k = list(range(1, len(c.residuals) + 1))
    ax.plot(k, [r.before for r in c.residuals], "o", ms=4, color="0.55", label="before the fit")
    ax.plot(k, [r.after for r in c.residuals], "o", ms=4, color="tab:blue", label="after the fit")
    if all(r.after > 0 for r in c.residuals if math.isfinite(r.after)):   # sizes: a log scale shows both
        from matplotlib.ticker import FuncFormatter
        ax.set_yscale("log")
        ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))   # not mathtext: drawn as written
    ax.set_xlabel("pose (in the order measured)")
    ax.set_ylabel(f"residual [{c.residual_unit}]")
    ax.grid(alpha=0.3)
    ax.legend(loc="lower left", bbox_to_anchor=(0.0, 1.0), ncol=2, frameon=False)   # above: no point hidden
    return fig


def _dispersion_figure(c: Calibration):
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(max(4.0, 1.1 * len(c.dispersion) + 2), 3.2), dpi=100)
    x = range(len(c.dispersion))
    ax.bar([i - 0.2 for i in x], [d.before for d in c.dispersion], 0.4, color="0.6", label="before")
    ax.bar([i + 0.2 for i in x], [d.after for d in c.dispersion], 0.4, color="tab:blue", label="after")
    ax.set_xticks(list(x), [d.axis for d in c.dispersion])
    ax.set_ylabel(f"dispersion [{c.residual_unit}]")
    ax.legend()
    return fig


def _values_figure(c: Calibration):
    """One panel per unit: values of different units on one axis would compare nothing."""
    plt = _pyplot()
    units = list(dict.fromkeys(v.unit for v in c.values))
    count = [sum(v.unit == u for v in c.values) for u in units]
    fig, axes = plt.subplots(len(units), 1, figsize=(8, 0.9 + 0.32 * sum(count) + 0.6 * len(units)), dpi=100,
                             squeeze=False, gridspec_kw={"height_ratios": count})
    for ax, u in zip(axes[:, 0], units):
        vs = [v for v in c.values if v.unit == u][::-1]
        y = range(len(vs))
        ax.errorbar([v.value for v in vs], list(y), xerr=[2 * v.uncertainty for v in vs], fmt="o",
                    color="tab:blue", capsize=3)
        ax.axvline(0, color="0.5", lw=0.8)
        ax.set_yticks(list(y), [v.name for v in vs])
        ax.set_ylim(-0.6, len(vs) - 0.4)
        ax.set_xlabel(f"value ± 2 standard uncertainties [{u}]")
        ax.grid(axis="x", alpha=0.3)
    fig.tight_layout()
    return fig


def _correlation_figure(c: Calibration):
    plt = _pyplot()
    n = len(c.values)
    size = min(9.0, 2.5 + 0.3 * n)
    fig, ax = plt.subplots(figsize=(size + 1.2, size), dpi=100)
    mesh = ax.imshow(c.correlation, vmin=-1, vmax=1, cmap="RdBu_r")
    names = [v.name for v in c.values]
    ax.set_xticks(range(n), names, rotation=90, fontsize="small")
    ax.set_yticks(range(n), names, fontsize="small")
    fig.colorbar(mesh, ax=ax, label="correlation")
    return fig
