"""Values as a person reads them: the one place that turns internal values into printed text.

Internally every length is in mm, every angle in rad, every ratio in 1 (see ``units``). The
errors of a machine are µm and arcsecond sized, so by default they are shown in µm, arcsec and
µm/m ("people" units); ``--units internal`` shows mm, rad and 1 with full digits, for scripts and
comparisons. JSON output never goes through here: it stays in internal units and says so.

API (``kind`` is a unit kind of ``chaincomp.units``: "length", "angle" or "ratio"):

- ``UNIT_SYSTEMS``, ``DEFAULT_UNITS``: the choices of ``--units`` ("people", "internal").
- ``add_units_argument(parser)``: the ``--units`` option, the same in every verb that prints errors.
- ``display_unit(kind, units="people")``: the ``Unit`` shown (µm, arcsec, µm/m, or mm, rad, 1).
- ``convert(value, kind, units="people")``: ``(value in that unit, unit name)``; value may be
  a number or a numpy array.
- ``quantity(value, kind, units="people", decimals=None)``: ``"2.405 µm"`` with the unit's
  fixed number of decimals (``DECIMALS``: a column of values lines up and shows the same
  resolution, 1 nm, 0.001 arcsec; internal units keep 9 to 12 decimals).
- ``fixed(value, decimals, width=0)``: ``f"{value:{width}.{decimals}f}"`` without a ``-0.000``.
- ``plus_minus(value, u)``: ``"4.60 ± 0.21"``: the uncertainty rounded to 2 significant digits,
  the estimate rounded to the same decimal place (half away from zero, on the shortest decimal
  text of each float, so 0.0041 is 0.0041 and not its binary neighbour). Outside 1e-4..1e6 a
  shared exponent: ``"(4.60 ± 0.21)e-07"``. An uncertainty of 0 gives 6 significant digits;
  an infinite or undefined one ``"4.6 ± inf"``; a negative one is a ValueError; one below the
  17th significant digit of the estimate (finer than a double holds) ``"5.0 ± 1.0e-20"``.
- ``uncertain(value, u, kind=None, units="people")``: the same with both converted from
  internal units and the unit appended: ``"4.60 ± 0.21 µm"``.
"""

from __future__ import annotations

import math
from decimal import ROUND_HALF_UP, Decimal

from .units import INTERNAL, UNITS, Unit

UNIT_SYSTEMS = ("people", "internal")
DEFAULT_UNITS = "people"

_PEOPLE = {"length": UNITS["µm"], "angle": UNITS["arcsec"], "ratio": Unit("µm/m", "ratio", 1e-6)}
_DOUBLE_DIGITS = 17   # significant decimal digits that tell any two doubles apart
DECIMALS = {"µm": 3, "arcsec": 3, "µm/m": 3, "mm": 9, "rad": 12, "1": 12}


def add_units_argument(p) -> None:
    p.add_argument("--units", choices=UNIT_SYSTEMS, default=DEFAULT_UNITS,
                   help="units of the printed errors: people (µm, arcsec, µm/m; default) or internal "
                        "(mm, rad, 1, full digits); JSON is always internal")


def display_unit(kind: str, units: str = DEFAULT_UNITS) -> Unit:
    if units not in UNIT_SYSTEMS:
        raise ValueError(f"units must be one of {', '.join(UNIT_SYSTEMS)}, got {units!r}")
    return _PEOPLE[kind] if units == "people" else UNITS[INTERNAL[kind]]


def convert(value, kind: str, units: str = DEFAULT_UNITS):
    u = display_unit(kind, units)
    return value / u.to_internal, u.name


def quantity(value: float, kind: str, units: str = DEFAULT_UNITS, decimals: int | None = None) -> str:
    v, name = convert(value, kind, units)
    return f"{fixed(v, DECIMALS[name] if decimals is None else decimals)} {name}"


def fixed(value: float, decimals: int, width: int = 0) -> str:
    return f"{_no_negative_zero(f'{value:.{decimals}f}'):>{width}}"


def uncertain(value: float, u: float, kind: str | None = None, units: str = DEFAULT_UNITS) -> str:
    if kind is None:
        return plus_minus(value, u)
    unit = display_unit(kind, units)
    return f"{plus_minus(value / unit.to_internal, u / unit.to_internal)} {unit.name}"


def plus_minus(value: float, u: float) -> str:
    value, u = float(value), float(u)   # numpy's floats: repr() is 'np.float64(...)', no decimal text
    if u < 0:
        raise ValueError(f"an uncertainty is not negative, got {u!r}")
    if not math.isfinite(value):
        return f"{value} ± {u:.2g}" if math.isfinite(u) else f"{value} ± {u}"
    if not math.isfinite(u):
        return f"{value:.2g} ± {u}"
    if u == 0:
        return f"{_no_negative_zero(f'{value:.6g}')} ± 0"
    du = Decimal(repr(u))
    place = du.adjusted() - 1                       # the decimal exponent of u's 2nd significant digit
    if value and Decimal(repr(value)).adjusted() - place > _DOUBLE_DIGITS:
        # u is below the estimate's last digit a double holds: no digits to round it to
        # (and more than the 28 digits of decimal's default context)
        return f"{value!r} ± {u:.1e}"
    ur = du.quantize(Decimal(1).scaleb(place), rounding=ROUND_HALF_UP)
    if ur.adjusted() > du.adjusted():               # 0.0996 -> 0.10: still 2 significant digits
        place += 1
        ur = du.quantize(Decimal(1).scaleb(place), rounding=ROUND_HALF_UP)
    vr = Decimal(repr(value)).quantize(Decimal(1).scaleb(place), rounding=ROUND_HALF_UP)
    top = max(ur.adjusted(), vr.adjusted() if vr else ur.adjusted())
    if -4 <= top < 6:
        return f"{_no_negative_zero(_plain(vr))} ± {_plain(ur)}"
    # a shared power of ten: both mantissas keep the same decimal place
    shift, step = Decimal(1).scaleb(-top), Decimal(1).scaleb(place - top)
    vm, um = (vr * shift).quantize(step), (ur * shift).quantize(step)
    return f"({_no_negative_zero(_plain(vm))} ± {_plain(um)})e{top:+03d}"


def _plain(d: Decimal) -> str:
    return f"{d:f}"


def _no_negative_zero(text: str) -> str:
    """'-0.00' is zero: a sign the rounding removed the reason for."""
    return text[1:] if text.startswith("-") and not text.strip("-0.") else text
