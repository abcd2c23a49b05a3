"""Random machine chains of every compensation solver shape, for the never-worse property test
(tests/python/emit/test_never_worse.py) and its longer run in tools/bench_codegen: each shape a
machine file written here plus a numpy model of the same chain (the truth the tests hold the
built library to), and the documented objective (docs/guide/daemon.md, "The objective")."""

import math

import numpy as np

DEG = math.pi / 180
ARCSEC = DEG / 3600
WEIGHT = 100.0  # mm per rad: the documented objective's direction weight


# ---- the chains: elements ("T", (x, y, z)) and ("R", "x"|"y"|"z", angle), expressions in the
# symbols' internal units (mm, rad), written into the machine file and evaluated by numpy ----

def linear(axis):
    """A slide: positioning, two straightness errors and two tilts."""
    i = "XYZ".index(axis)
    t = [f"E{c}{axis}" for c in "XYZ"]
    t[i] = f"{axis} + {t[i]}"
    tilts = [a for a in "xyz" if a != axis.lower()]
    return ([("T", tuple(t))] + [("R", a, f"R{a}{axis}") for a in tilts],
            [f"E{c}{axis}" for c in "XYZ"], [f"R{a}{axis}" for a in tilts])


def rotary(axis, about, sign=1):
    """A rotary axis about x, y or z through the origin: its line's position (two errors),
    orientation (two tilts) and zero error; a table turns by minus its angle."""
    others = [a for a in "xyz" if a != about]
    pos = {a: f"P{a}{axis}" for a in others}
    tilts = [f"T{a}{axis}" for a in others]
    angle = f"{'-' if sign < 0 else ''}({axis} + Z0{axis})"
    elements = [("T", tuple(pos.get(a, "0") for a in "xyz"))]
    elements += [("R", a, t) for a, t in zip(others, tilts)]
    elements += [("R", about, angle)]
    return elements, list(pos.values()), tilts + [f"Z0{axis}"]


def offset(*xyz):
    return [("T", tuple(xyz))], [], []


class Shape:
    def __init__(self, name, axes, parts, constants, tool_frame=False, corrects_all=False, singular=None):
        self.name = name
        self.axes = axes            # (name, kind "mm"/"deg", lower, upper)
        self.chain, self.length_errors, self.angle_errors = [], [], []
        for elements, lengths, angles in parts:
            self.chain += elements
            self.length_errors += lengths
            self.angle_errors += angles
        self.constants = constants  # name -> (unit, nominal, low, high), the random geometry
        self.tool_frame = tool_frame
        self.corrects_all = corrects_all  # its axes can hold the whole pose (away from singular poses)
        self.singular = singular or {}    # axis -> singular value (deg): commands are drawn near it

    def yaml(self):
        lines = [f"name: {self.name}", f"description: never-worse test shape {self.name}", "length_unit: mm",
                 "rotation_sense: right_hand", "symbols:"]
        for name, unit, lo, hi in self.axes:
            lines.append(f"  - {{name: {name}, role: axis, unit: {unit}, limits: [{lo}, {hi}]}}")
        for name, (unit, nominal, _, _) in self.constants.items():
            lines.append(f"  - {{name: {name}, role: constant, unit: {unit}, nominal: {nominal}}}")
        lines += [f"  - {{name: {e}, role: error, unit: um}}" for e in self.length_errors]
        lines += [f"  - {{name: {e}, role: error, unit: arcsec}}" for e in self.angle_errors]
        lines.append("chain:")
        for el in self.chain:
            if el[0] == "T":
                lines.append(f"  - {{translate: [{', '.join(el[1])}]}}")
            else:
                lines.append(f"  - {{rotate: {el[1]}, angle: '{el[2]}'}}")
        lines += ["tool:", "  point: [0, 0, 0]", "  direction: [0, 0, 1]"]
        if self.tool_frame:
            lines.append("  reference: [1, 0, 0]")
        return "\n".join(lines) + "\n"

    def pose(self, values):
        """Tool point, direction and (with a frame) the frame's x axis: the chain's product
        applied to the tool, by numpy."""
        env = dict(values, __builtins__={})
        M = np.eye(4)
        for el in self.chain:
            if el[0] == "T":
                step = np.eye(4)
                step[:3, 3] = [eval(e, env) for e in el[1]]  # the test's own expressions
            else:
                a = eval(el[2], env)
                c, s = math.cos(a), math.sin(a)
                i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[el[1]]
                step = np.eye(4)
                step[i, i], step[i, j], step[j, i], step[j, j] = c, -s, s, c
            M = M @ step
        return M[:3, 3], M[:3, 2], M[:3, 0]


def _mm(name, lo, hi):
    return (name, "mm", lo, hi)


def _deg(name, lo, hi):
    return (name, "deg", lo, hi)


XYZ = [_mm("X", -300, 300), _mm("Y", -300, 300), _mm("Z", -300, 300)]
SLIDES = [linear("X"), linear("Y"), linear("Z")]
TOOL = {"L": ("mm", 100, 20, 300)}
SHAPES = [
    # three slides: the point is corrected, the tilt cannot be and is reported
    Shape("nw_xyz", XYZ, SLIDES + [offset("0", "0", "-L")], TOOL),
    # three slides and one rotary axis: head about x, table about y
    Shape("nw_xyz_a", XYZ + [_deg("A", -120, 120)],
          SLIDES + [offset("0", "0", "-H"), rotary("A", "x"), offset("0", "e", "-L")],
          {"H": ("mm", 150, 50, 300), "e": ("mm", 10, -50, 50), **TOOL}),
    Shape("nw_b_xyz", [_deg("B", -120, 120)] + XYZ,
          [rotary("B", "y", -1), offset("0", "0", "h")] + SLIDES + [offset("0", "0", "-L")],
          {"h": ("mm", 50, 0, 200), **TOOL}),
    # head-head C then A (tool along C at A = 0: singular)
    Shape("nw_xyz_ca", XYZ + [_deg("C", -360, 360), _deg("A", -110, 110)],
          SLIDES + [rotary("C", "z"), offset("0", "e", "-G"), rotary("A", "x"), offset("0", "0", "-L")],
          {"e": ("mm", 10, -50, 50), "G": ("mm", 100, 0, 200), **TOOL}, corrects_all=True, singular={"A": 0}),
    # table-table A carrying C (C along the tool at A = 0)
    Shape("nw_ac_xyz", [_deg("C", -360, 360), _deg("A", -120, 120)] + XYZ,
          [rotary("C", "z", -1), offset("0", "0", "-hC"), rotary("A", "x", -1)] + SLIDES + [offset("0", "0", "-L")],
          {"hC": ("mm", 50, 0, 200), **TOOL}, corrects_all=True, singular={"A": 0}),
    # mixed: C table, B head
    Shape("nw_c_xyz_b", [_deg("C", -360, 360)] + XYZ + [_deg("B", -110, 110)],
          [rotary("C", "z", -1)] + SLIDES + [offset("0", "0", "-G"), rotary("B", "y"), offset("0", "0", "-L")],
          {"G": ("mm", 150, 0, 300), **TOOL}, corrects_all=True, singular={"B": 0}),
    # nutating table: B about an axis at n (45 degrees) from z in the yz plane, C on it
    Shape("nw_nutating", [_deg("C", -360, 360), _deg("B", -180, 180)] + XYZ,
          [rotary("C", "z", -1), ([("R", "x", "n")], [], []), rotary("B", "z", -1), ([("R", "x", "-n")], [], [])]
          + SLIDES + [offset("0", "0", "-L")],
          {"n": ("deg", 45, 45, 45), **TOOL}, corrects_all=True, singular={"B": 0}),
    # a six-joint arm with a spherical wrist (z-y-z: singular at q5 = 0; the elbow at q3 = 0)
    Shape("nw_arm6", [_deg(f"q{i}", -360, 360) for i in range(1, 7)],
          [rotary("q1", "z"), offset("0", "0", "d1"), rotary("q2", "y"), offset("0", "0", "a2"),
           rotary("q3", "y"), offset("0", "0", "a3"), rotary("q4", "z"), rotary("q5", "y"), rotary("q6", "z"),
           offset("0", "0", "d6")],
          {"d1": ("mm", 90, 50, 200), "a2": ("mm", 425, 200, 600), "a3": ("mm", 390, 200, 600),
           "d6": ("mm", 80, 40, 150)}, tool_frame=True, corrects_all=True, singular={"q5": 0, "q3": 0}),
    # a seven-joint arm (shoulder q1-q3, elbow q4, wrist q5-q7; a frame): more axes than the pose,
    # the null space's turn left at the command. Singular: the elbow straight (q4 = 0), and q1
    # on q3 (q2 = 0) or q5 on q7 (q6 = 0) where the other alignment leaves no spare joint
    Shape("nw_arm7", [_deg(f"q{i}", -360, 360) for i in range(1, 8)],
          [rotary("q1", "z"), offset("0", "0", "d1"), rotary("q2", "y"), rotary("q3", "z"), offset("0", "0", "a2"),
           rotary("q4", "y"), rotary("q5", "z"), offset("0", "0", "a3"), rotary("q6", "y"), rotary("q7", "z"),
           offset("0", "0", "d7")],
          {"d1": ("mm", 340, 200, 400), "a2": ("mm", 400, 300, 500), "a3": ("mm", 400, 300, 500),
           "d7": ("mm", 126, 80, 200)}, tool_frame=True, corrects_all=True, singular={"q2": 0, "q4": 0, "q6": 0}),
]
# Fewer axes than the pose (a three-joint arm holding its tool's point and direction: three
# axes for five conditions): where they cannot hold both, the direction weight decides the
# compromise. Not among SHAPES: its optimum may move the point to turn the direction.
ARM3 = Shape("nw_arm3", [_deg("q1", -360, 360), _deg("q2", -150, 150), _deg("q3", -150, 150)],
             [rotary("q1", "z"), offset("0", "0", "d1"), rotary("q2", "y"), offset("0", "0", "a2"),
              rotary("q3", "y"), offset("0", "0", "a3")],
             {"d1": ("mm", 90, 50, 200), "a2": ("mm", 425, 200, 600), "a3": ("mm", 390, 200, 600)},
             singular={"q3": 0})
BY_NAME = {s.name: s for s in SHAPES}


def internal(shape, unit, value):
    return value * DEG if unit == "deg" else value


def errors_of(shape, draws):
    """Errors of up to 5 µm and 5 arcsec (internal units)."""
    names = shape.length_errors + shape.angle_errors
    return {n: d * (0.005 if n in shape.length_errors else 5 * ARCSEC) for n, d in zip(names, draws)}


def command_of(shape, kind, draws):
    """Axes (internal units): anywhere within the limits, 0.1-30 degrees from a singular
    value, or with one axis at a limit."""
    q = []
    for (name, unit, lo, hi), d in zip(shape.axes, draws):
        q.append(internal(shape, unit, lo + (hi - lo) * d))
    if kind == "near_singular" and shape.singular:
        axis, value = sorted(shape.singular.items())[int(draws[-1] * 997) % len(shape.singular)]
        i = [a[0] for a in shape.axes].index(axis)
        distance = 0.1 * (300 ** draws[-2])  # 0.1 to 30 degrees, log-uniform
        q[i] = (value + (distance if draws[-3] > 0.5 else -distance)) * DEG
    elif kind == "at_limit":
        i = int(draws[-1] * 997) % len(shape.axes)
        name, unit, lo, hi = shape.axes[i]
        q[i] = internal(shape, unit, hi if draws[-2] > 0.5 else lo)
    return np.array(q)


def pose_error(shape, actual, nominal):
    """The point error (mm) and the direction error (rad) as docs/guide/daemon.md defines them:
    with a frame, the orientation residual |zt x za + (yt . xa) zt| (yt = zt x xt; the rotation
    angle between the frames to first order: the two differ at the second order, for a 1e-4 rad
    residual, more than the 1e-9 the tests compare to); else the change of the direction."""
    p, z, x = actual
    pt, zt, xt = nominal
    point = float(np.linalg.norm(p - pt))
    if shape.tool_frame:
        yt = np.cross(zt, xt)
        direction = float(np.linalg.norm(np.cross(zt, z) + np.dot(yt, x) * zt))
    else:
        direction = float(np.linalg.norm(z - zt))
    return point, direction


def objective(point, direction, weight=WEIGHT):
    return point ** 2 + (weight * direction) ** 2


def far_from_singular(shape, q):
    names = [a[0] for a in shape.axes]
    for axis, value in shape.singular.items():
        if abs(math.sin(q[names.index(axis)] - value * DEG)) < math.sin(30 * DEG):
            return False
    return True




def score(shape, lib, draws, signs, kind):
    """One random case on a built library (test_build_solver.Loaded): the geometry from draws[40:],
    errors from signs, the command of `kind` from draws. Returns (status, corrected, residual,
    before, after, geometry, errors, q, nominal): before/after the (point, direction) error."""
    geometry = {c: internal(shape, u, lo + (hi - lo) * d)
                for (c, (u, _, lo, hi)), d in zip(shape.constants.items(), draws[40:])}
    errors = errors_of(shape, signs)
    lib.prepare({**geometry, **errors})
    q = command_of(shape, kind, draws)
    names = [a[0] for a in shape.axes]
    zero = {e: 0.0 for e in shape.length_errors + shape.angle_errors}
    nominal = shape.pose({**geometry, **zero, **dict(zip(names, q))})
    residual = np.zeros(2)
    status, corrected = lib.compensate(q, residual)
    before = pose_error(shape, shape.pose({**geometry, **errors, **dict(zip(names, q))}), nominal)
    after = pose_error(shape, shape.pose({**geometry, **errors, **dict(zip(names, corrected))}), nominal)
    return status, corrected, residual, before, after, geometry, errors, q, nominal
