"""Titles, labels and units of every chaincomp figure, in one place: each figure says which
machine, which error values, which model, and where the axes it does not draw were held; each
axis and colour bar names its quantity and one unit in brackets."""

from __future__ import annotations

import io
import os
import re
import sys

from ..model.display import DEFAULT_UNITS, display_unit
from ..model.units import UNITS
from ..output import write_file

ORDER_TEXT = {"1": "first-order", "2": "second-order", "exact": "exact",
              "first": "first-order", "second": "second-order"}

# What a map of each tool-error component shows, and the kind of its unit. dk*: the change of
# the unit tool axis, which for small errors is its tilt (rad) towards x, y or z.
COMPONENT_TEXT = {"dx": "dx", "dy": "dy", "dz": "dz", "norm": "|tool point error|",
                  "dkx": "dkx (tool axis tilt towards x)", "dky": "dky (tool axis tilt towards y)",
                  "dkz": "dkz (tool axis tilt towards z)"}


def use_agg() -> None:
    """matplotlib without a display, every text drawn as written: titles carry file names and
    --set values, whose $ would otherwise start mathtext (and a stray one stop the verb)."""
    import matplotlib
    matplotlib.use("Agg")
    matplotlib.rcParams["text.parse_math"] = False


def model_text(model: str) -> str:
    """'1' -> 'first-order model'; 'exact-first' or 'exact-1' -> 'exact minus first-order model'."""
    return " minus ".join(ORDER_TEXT[m] for m in model.split("-")) + " model"


def values_text(params: str | None, sets=(), axes=()) -> str:
    """Where the error values came from: the params file's name and any --set (but those of
    the axes, which the held axes show)."""
    parts = [f"params {os.path.basename(params)}" if params else "no --params"]
    sets = [s for s in sets if s.partition("=")[0].strip() not in axes]
    if sets:
        parts.append("--set " + ", ".join(s.replace(" ", "") for s in sets))
    return ", ".join(parts)


def held_text(machine, values: dict, drawn) -> str:
    """The axes not drawn, at their values (declared units): 'Ap = 30 deg, Cp = 40 deg'."""
    held = [a for a in machine.axes if a.name not in drawn]
    return ", ".join(f"{a.name} = {a.from_internal(values[a.name]):g} {a.unit.name}" for a in held)


def title(machine, what: str, params: str | None = None, sets=(), model: str | None = None,
          held: str | None = None, extra: str | None = None) -> str:
    """Two lines: '<machine>: <what>' and the model, the values and the axes held. machine: a
    Machine, or a name where there is none."""
    name, axes = (machine, ()) if isinstance(machine, str) else (machine.name, [a.name for a in machine.axes])
    second = [model_text(model)] if model else []
    second.append(values_text(params, sets, axes))
    if held:
        second.append(f"held: {held}")
    if extra:
        second.append(extra)
    return f"{name}: {what}\n" + "; ".join(second)


def lines(text: str, width: int) -> str:
    """Text broken at its '; ' and ', ' into lines of about ``width`` characters (a title over a
    narrow panel)."""
    out: list[str] = []
    for part in re.split(r"(?<=[;,]) ", text):
        if out and len(out[-1]) + 1 + len(part) <= width:
            out[-1] += " " + part
        else:
            out.append(part)
    return "\n".join(out)


def label(quantity: str, unit: str) -> str:
    return f"{quantity} [{unit}]"


def axis_label(symbol) -> str:
    return label(symbol.name, symbol.unit.name)


def component_unit(component: str, length_unit: str, units: str = DEFAULT_UNITS) -> tuple[float, str]:
    """(factor, unit) that turn a component in the machine's length unit (dk*: unitless) into
    the unit shown: µm and arcsec for people, mm and rad internally."""
    kind = "angle" if component.startswith("dk") else "length"
    shown = display_unit(kind, units)
    to_internal = UNITS[length_unit].to_internal if kind == "length" else 1.0
    return to_internal / shown.to_internal, shown.name


def save(fig, path: str, **options) -> None:
    """Write a matplotlib figure (its type from the file name, PNG without one). The canvas is
    the drawing's bounding box (bbox_inches="tight"): no title, label or key is cut at its edge
    whatever its length. Drawn in memory first, so that a failed write (a full disk, a folder
    that takes no files) is an error naming the file, not a traceback or a silently short image."""
    kind = os.path.splitext(path)[1].lstrip(".").lower() or "png"
    buffer = io.BytesIO()
    fig.savefig(buffer, format=kind, **{"bbox_inches": "tight", "pad_inches": 0.15, **options})
    write_file(path, buffer.getvalue())


def warn(message: str) -> None:
    print(f"chaincomp: warning: {message}", file=sys.stderr)
