"""Units at the edges: every value is held internally in mm (length) or rad (angle)."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Unit:
    name: str
    kind: str          # "length", "angle" or "ratio"
    to_internal: float  # multiply a value in this unit by this to get mm / rad / 1


_UNITS = [
    Unit("mm", "length", 1.0),
    Unit("m", "length", 1000.0),
    Unit("um", "length", 1e-3),
    Unit("µm", "length", 1e-3),
    Unit("nm", "length", 1e-6),
    Unit("in", "length", 25.4),
    Unit("rad", "angle", 1.0),
    Unit("deg", "angle", math.pi / 180.0),
    Unit("mrad", "angle", 1e-3),
    Unit("urad", "angle", 1e-6),
    Unit("µrad", "angle", 1e-6),
    Unit("arcsec", "angle", math.pi / (180.0 * 3600.0)),
    Unit("1", "ratio", 1.0),
    Unit("ppm", "ratio", 1e-6),
]
UNITS = {u.name: u for u in _UNITS}
INTERNAL = {"length": "mm", "angle": "rad", "ratio": "1"}


def unit(name: str) -> Unit:
    """The unit called ``name``; KeyError with the list of known ones otherwise."""
    try:
        return UNITS[name]
    except KeyError:
        hint = ""
        if isinstance(name, str) and "\u03bc" in name:   # Greek mu: looks the same as the micro sign
            hint = ("; it is written with the Greek letter mu (U+03BC): write the micro sign \u00b5 (U+00B5) "
                    f"or u, e.g. {name.replace(chr(0x3bc), 'u')!r}")
        raise KeyError(f"unknown unit {name!r} (expected one of: {', '.join(UNITS)}){hint}") from None
