"""Independent readers/replayers for firmware skew-compensation commands.

Written for the tests of chaincomp export from the firmwares documented behaviour (no firmware code copied).
Sources:
  Klipper3d/klipper @84104bbb: klippy/extras/skew_correction.py, docs/G-Codes.md, docs/Skew_Correction.md
  MarlinFirmware/Marlin: Marlin/src/gcode/calibrate/M852.cpp @0ce0d2c7, Marlin/src/module/planner.h skew(),
      Conditionals_post.h _SKEW_FACTOR, Configuration.h SKEW_CORRECTION comments
  Duet3D/RepRapFirmware @fc1cd16c: src/GCodes/GCodes2.cpp (M556), src/Movement/Move.cpp AxisTransform
  https://duet3d.dozuki.com/Wiki/M556
Positions: numpy arrays of shape (3,) or (3, N); rows are x, y, z.
"""
import math
import re

import numpy as np

_WORD = re.compile(r"([A-Za-z])\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)")


def skew_factor_from_lengths(ac, bd, ad):
    """Tangent factor from a calibration parallelogram's diagonals AC, BD and side AD.

    Same geometry as Klipper calc_skew_factor / Marlin _SKEW_FACTOR. AB comes from the
    parallelogram law, theta_A comes from the law of cosines, and the factor is cot(theta_A) = tan(pi/2 - theta_A).
    A positive value means AC > BD, i.e. the printed angle at A is acute.
    """
    ab = math.sqrt(2 * ac * ac + 2 * bd * bd - 4 * ad * ad) / 2.0
    cos_a = (ac * ac - ab * ab - ad * ad) / (2 * ab * ad)
    return math.tan(math.pi / 2 - math.acos(cos_a))


def lengths_from_skew_factor(t, side=100.0):
    """Inverse of skew_factor_from_lengths for a rhombus with AB = AD = side -> (AC, BD, AD)."""
    theta = math.atan2(1.0, t)
    c = math.cos(theta)
    return side * math.sqrt(2 * (1 + c)), side * math.sqrt(2 * (1 - c)), side


def _strip_comment(line):
    return line.split(";", 1)[0].strip()


def parse_klipper(line):
    """Parse `SET_SKEW [XY=ac,bd,ad] [XZ=..] [YZ=..] [CLEAR=1]` (Klipper docs/G-Codes.md SET_SKEW).

    Returns {'xy':..,'xz':..,'yz':..}, containing only the planes given (Klipper keeps the others
    unchanged). CLEAR=1 returns all zeros. Each factor = skew_factor_from_lengths(ac, bd, ad)
    (klippy/extras/skew_correction.py cmd_SET_SKEW / calc_skew_factor).
    """
    s = _strip_comment(line)
    parts = s.split()
    if not parts or parts[0].upper() != "SET_SKEW":
        raise ValueError("not a SET_SKEW line: %r" % line)
    params = {}
    for p in parts[1:]:
        k, _, v = p.partition("=")
        params[k.upper()] = v
    if int(float(params.get("CLEAR", "0") or 0)):
        return {"xy": 0.0, "xz": 0.0, "yz": 0.0}
    out = {}
    for plane in ("XY", "XZ", "YZ"):
        if plane in params:
            vals = [float(x) for x in params[plane].split(",")]
            if len(vals) != 3:
                raise ValueError("plane %s needs 3 lengths" % plane)
            out[plane.lower()] = skew_factor_from_lengths(*vals)
    return out


def parse_marlin(line, min_factor=-1.0, max_factor=1.0, unit_factor=1.0, for_z=True):
    """Parse `M852 [I<xy>|S<xy>] [J<xz>] [K<yz>]` (Marlin M852.cpp).

    Factors are given directly as tangents. S is an alias for I, and I wins if both are given.
    Marlin reads them with parser.value_linear_units(): the value times the current length unit
    (``unit_factor``: 1 after G21, 25.4 after G20). Values outside [SKEW_FACTOR_MIN,
    SKEW_FACTOR_MAX] = [-1, 1] (after that scaling) are rejected, not clamped, and are left out of
    the result. J and K are read only in a Marlin built with SKEW_CORRECTION_FOR_Z (``for_z``).
    """
    s = _strip_comment(line)
    words = s.split(None, 1)
    if not words or words[0].upper() != "M852":
        raise ValueError("not an M852 line: %r" % line)
    w = {k.upper(): float(v) * unit_factor for k, v in _WORD.findall(words[1] if len(words) > 1 else "")}
    out = {}
    for key, letters in (("xy", ("I", "S")), ("xz", ("J",)), ("yz", ("K",))):
        if key != "xy" and not for_z:
            continue
        for L in letters:
            if L in w:
                if min_factor <= w[L] <= max_factor:
                    out[key] = w[L]
                break
    return out


def _commands(program):
    """(first word upper-cased, line) of each line of a G-code program that holds a command."""
    for line in program.splitlines():
        s = _strip_comment(line)
        if s:
            yield s.split(None, 1)[0].upper(), s


def replay_marlin(program, factors=None, inch=False, for_z=True):
    """The skew factors after a G-code program, from the state before it (``factors``, G20 in force
    if ``inch``): G20/G21 set the length unit M852 reads its values in (Marlin gcode/units/G20_G21.cpp
    set_input_linear_units: 25.4 or 1), and each M852 sets the factors it gives (M852.cpp)."""
    state = dict(factors or {"xy": 0.0, "xz": 0.0, "yz": 0.0})
    for word, line in _commands(program):
        if word in ("G20", "G21"):
            inch = word == "G20"
        elif word == "M852":
            state.update(parse_marlin(line, unit_factor=25.4 if inch else 1.0, for_z=for_z))
    if not for_z:
        state["xz"] = state["yz"] = 0.0   # planner.h skew() has no z terms without SKEW_CORRECTION_FOR_Z
    return state


def replay_rrf(program, state=None):
    """The axis compensation after a G-code program, from the state before it: each M556 sets the
    tangents it gives, and P only when P is given (GCodes2.cpp case 556): an earlier P1 stays."""
    state = dict(state or {"tanXY": 0.0, "tanYZ": 0.0, "tanXZ": 0.0, "compensateXY": True})
    for word, line in _commands(program):
        if word == "M556":
            state.update(parse_rrf(line))
    return state


def parse_rrf(line):
    """Parse `M556 S<len> [X<dev>] [Y<dev>] [Z<dev>] [P<n>]` (RRF GCodes2.cpp case 556; Duet M556 docs).

    Returns {'tanXY': X/S, 'tanYZ': Y/S, 'tanXZ': Z/S, 'compensateXY': bool}. The letter-to-pair mapping is
    X->XY, Y->YZ, Z->XZ (Move.h tangents[]). X/Y/Z are ignored without S. P0 (default) means the XY term
    corrects X, and P>0 means it corrects Y. Only the keys that were set are returned.
    """
    s = _strip_comment(line)
    words = s.split(None, 1)
    if not words or words[0].upper() != "M556":
        raise ValueError("not an M556 line: %r" % line)
    w = {k.upper(): float(v) for k, v in _WORD.findall(words[1] if len(words) > 1 else "")}
    out = {}
    if "S" in w:
        S = w["S"]
        if not S > 0:
            raise ValueError("M556 S must be positive")
        for letter, key in (("X", "tanXY"), ("Y", "tanYZ"), ("Z", "tanXZ")):
            if letter in w:
                out[key] = w[letter] / S
    if "P" in w:
        out["compensateXY"] = int(w["P"]) <= 0
    return out


def _xyz(xyz):
    a = np.asarray(xyz, dtype=float)
    return a.copy(), a.ndim == 1


def apply_klipper(factors, xyz):
    """Commanded -> motor position, Klipper skew_correction calc_skew (used in move()).

    x' = x - xy*y - (xz - xy*yz)*z ; y' = y - yz*z ; z' = z. This exactly inverts the shear
    model physical = [[1,xy,xz],[0,1,yz],[0,0,1]] @ motor.
    """
    p, _ = _xyz(xyz)
    xy, xz, yz = (float(factors.get(k, 0.0)) for k in ("xy", "xz", "yz"))
    x, y, z = p[0].copy(), p[1].copy(), p[2].copy()
    p[0] = x - y * xy - z * (xz - xy * yz)
    p[1] = y - z * yz
    return p


def klipper_refuses(factors, xyz, bounds):
    """Where Klipper refuses the move ("Move out of range"): skew_correction.py hands the
    kinematics the skewed position (calc_skew), and the kinematics' check_move refuses an end
    position outside a rail's [position_min, position_max]. bounds=(xmin, xmax, ymin, ymax); z is
    not skewed. A boolean per point."""
    q = apply_klipper(factors, xyz)
    x0, x1, y0, y1 = bounds
    return ~((q[0] >= x0) & (q[0] <= x1) & (q[1] >= y0) & (q[1] <= y1))


def apply_marlin(factors, xyz, bounds=None):
    """Commanded -> planner position, Marlin planner.h skew(), called first in apply_modifiers().

    The formula is the same as Klipper's. With bounds=(xmin, xmax, ymin, ymax) the Marlin window check is also
    replayed: the input must be within [min+1, max] and the result within [min, max] in both X and Y,
    otherwise the point passes through unchanged. The default (None) skips the check.
    """
    p, _ = _xyz(xyz)
    q = apply_klipper(factors, p)
    if bounds is None:
        return q
    x0, x1, y0, y1 = bounds
    ok = ((p[0] >= x0 + 1) & (p[0] <= x1) & (p[1] >= y0 + 1) & (p[1] <= y1)
          & (q[0] >= x0) & (q[0] <= x1) & (q[1] >= y0) & (q[1] <= y1))
    return np.where(ok, q, p)


def apply_rrf(factors, xyz):
    """User -> machine position, RRF Move::AxisTransform (applied before the bed transform).

    compensateXY (P0, default): x' = x + tXY*y + tXZ*z ; y' = y + tYZ*z.
    P1: x' = x + tXZ*z ; y' = y + tXY*x' + tYZ*z (Y uses the already-corrected X).
    """
    p, _ = _xyz(xyz)
    txy, tyz, txz = (float(factors.get(k, 0.0)) for k in ("tanXY", "tanYZ", "tanXZ"))
    comp_x = bool(factors.get("compensateXY", True))
    x, y, z = p[0].copy(), p[1].copy(), p[2].copy()
    if comp_x:
        p[0] = x + txy * y + txz * z
        p[1] = y + tyz * z
    else:
        p[0] = x + txz * z
        p[1] = y + txy * p[0] + tyz * z
    return p
