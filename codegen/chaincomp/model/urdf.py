"""A machine description from a URDF: the kinematic path from one link to another.

The URDF is read with yourdfpy (links, joints, types, axes, limits, mimic) from an XML tree
this module parses with a hardened lxml parser first: the file's size and element count
are bounded, DTDs and entities refused (a URDF needs neither; entities are how XML bombs
expand), and every element keeps its line for messages. Meshes are never loaded and no
scene graph is built: only the joints matter.

Each joint on the path base -> tip becomes, in the machine format (internal units mm, rad):

    origin xyz (m)    {translate: [x, y, z]}  in mm, the decimal as written scaled by 1000
    origin rpy        {rotate: z, angle: yaw}, {rotate: y, angle: pitch}, {rotate: x, angle: roll}
                      (URDF's R = Rz(yaw)·Ry(pitch)·Rx(roll)); numbers as written, zeros left out
    --errors origins  {errors: {dx .. ez}, order: txyz}: a 6-DOF block at the joint's origin
    revolute about an axis along +-x, +-y or +-z: {rotate: x|y|z, angle: +-(q + q_zero)}
    revolute about any other unit axis u: a constant frame change that takes z onto u, the
                      rotation about z, and its inverse: Rz(phi)·Ry(theta)·Rz(q)·Ry(-theta)·Rz(-phi),
                      phi = atan2(uy, ux), theta = atan2(sqrt(ux^2 + uy^2), uz): exact expressions
    prismatic         {translate: u·(q + q_zero)}

Error symbols (--errors, a joint mode and any of the blocks tool and base, separated by commas),
per moving joint J (its name sanitised; x, y, z, kx, ky, kz, the
measured coordinates' names, become x_ .. kz_ as reserved words do): joint-offsets gives
J_zero (arcsec, or um for a prismatic joint) added to the joint's motion; origins gives
J_dx, J_dy, J_dz (um), J_ex, J_ey, J_ez (arcsec), the block T(d)·Rx·Ry·Rz after the
joint's origin and before its motion (a fixed joint gets none: its origin error is the next
block's); all gives both (J_zero and the block's rotation about the joint's axis then have
the same gain where the axis is x, y or z: only their sum can be identified). tool gives
tool_dx .. tool_ez, a block at the end of the chain in the tip link's frame (the mount of a
camera, an SMR nest, a spindle); base gives base_dx .. base_ez, a block at its start marked
``registration: true``: where the measuring instrument's frame has the base (identified with
the errors, reported apart, never compensated).

Numbers are folded into the chain as exact decimals (the parser makes them rationals), so
the file holds exactly the values the URDF states. Axes: revolute in deg (limits rad -> deg),
continuous in deg with limits [-360, 360] (it has none), revolute limits rounded to
1e-9 deg, prismatic in mm (limits m -> mm).
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
from dataclasses import dataclass
from decimal import Decimal

from ..errors import ChaincompError
from ..escape import one_line, yaml_scalar
from .expressions import MAX_LITERAL, NAME, RESERVED
from .machine import MAX_CHAIN_ELEMENTS, MAX_SYMBOLS
from .yamlsource import read_text

MAX_ELEMENTS = 50_000       # XML elements of one URDF (a humanoid's has a few thousand)
MIN_MAGNITUDE = 1e-27      # smallest non-zero number: the machine format's 1e-30, in metres
ERROR_MODES = ("none", "joint-offsets", "origins", "all")
ERROR_BLOCKS = ("tool", "base")   # added to a mode: --errors origins,tool,base
MOVING = ("revolute", "continuous", "prismatic")
CONTINUOUS_LIMIT_DEG = 360.0
_BLOCK = ("dx", "dy", "dz", "ex", "ey", "ez")
BLOCK_SYMBOLS = tuple(f"{b}_{k}" for b in ERROR_BLOCKS for k in _BLOCK)   # tool_dx .. base_ez
_START_TAG = re.compile(r"<[A-Za-z_]")


@dataclass(frozen=True)
class PathJoint:
    """A joint of the path base -> tip, with what the machine file needs of it."""
    name: str           # as in the URDF
    axis_name: str      # sanitised to the machine format's NAME rule ('' for a fixed joint)
    type: str
    line: int
    xyz: tuple          # metres, as floats
    rpy: tuple          # rad, as floats
    axis: tuple         # direction as written (normalised where the chain uses it)
    limits: tuple | None  # in the axis' unit (deg, mm)
    inverted: bool = False  # a fixed joint above --base, walked up: its origin's inverse


class _Source:
    def __init__(self, path: str, text: str):
        self.path, self.text = path, text

    def fail(self, message: str, line: int | None = None, fld: str | None = None) -> ChaincompError:
        return ChaincompError(message, self.path, line, fld)


def _parse_xml(src: _Source):
    """The <robot> element, parsed without DTDs, entities, network or recovery."""
    from lxml import etree
    for marker in ("<!DOCTYPE", "<!ENTITY"):
        at = src.text.find(marker)
        if at >= 0:
            raise src.fail(f"{marker[2:]} declarations are refused (a URDF needs none; entities can expand "
                           "without bound)", src.text.count("\n", 0, at) + 1)
    elements = len(_START_TAG.findall(src.text))
    if elements > MAX_ELEMENTS:
        raise src.fail(f"{elements} XML elements (at most {MAX_ELEMENTS})")
    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False, huge_tree=False,
                             remove_comments=True, remove_pis=True)
    try:
        root = etree.fromstring(src.text.encode("utf-8"), parser=parser)
    except etree.XMLSyntaxError as exc:
        raise src.fail(f"XML syntax error: {exc.msg}", exc.lineno) from None
    if root.tag != "robot":
        hint = " (a xacro file: expand it first, 'xacro IN.urdf.xacro > OUT.urdf')" if "xacro" in src.text else ""
        raise src.fail(f"the root element is <{root.tag}>, expected <robot>{hint}", root.sourceline)
    macro = next((e for e in root.iter() if isinstance(e.tag, str) and "xacro" in e.tag), None)
    if macro is not None:
        raise src.fail("a xacro element: expand the file first ('xacro IN.urdf.xacro > OUT.urdf')",
                       macro.sourceline)
    return root


def _named(src: _Source, root, tag: str) -> dict:
    """<tag name=...> children of <robot> by name; a missing or repeated name is refused."""
    out = {}
    for el in root.findall(tag):
        name = el.get("name")
        if not name:
            raise src.fail(f"a <{tag}> without a name", el.sourceline, tag)
        if name in out:
            raise src.fail(f"{tag} {name!r} is defined twice (first on line {out[name].sourceline})",
                           el.sourceline, f"{tag} {name}")
        out[name] = el
    return out


# a joint's children that URDF allows once
_SINGLE = ("parent", "child", "origin", "axis", "limit", "mimic", "calibration", "dynamics", "safety_controller")


def _read_model(src: _Source, root):
    """yourdfpy's links and joints of the tree, each element read on its own so that a
    value it cannot read is reported with the element's line."""
    import yourdfpy
    links, joints = _named(src, root, "link"), _named(src, root, "joint")
    for name, el in joints.items():
        for part in _SINGLE:   # yourdfpy (and this reader) would take the first and drop the others
            found = el.findall(part)
            if len(found) > 1:
                raise src.fail(f"joint {name!r} has {len(found)} <{part}> elements (first on line "
                               f"{found[0].sourceline}): a joint has at most one", found[1].sourceline,
                               f"joint {name}.{part}")
        for part in ("parent", "child"):
            sub = el.find(part)
            if sub is None or not sub.get("link"):
                raise src.fail(f"joint {name!r} has no <{part} link=...>", el.sourceline, f"joint {name}")
            if sub.get("link") not in links:
                raise src.fail(f"joint {name!r}: its {part} link {sub.get('link')!r} is not defined",
                               sub.sourceline, f"joint {name}.{part}")
    parsed = {}
    for name, el in joints.items():
        _joint_numbers(src, el, name)   # before yourdfpy, which names no line
        _origin_numbers(src, el, name)
        try:
            parsed[name] = yourdfpy.URDF._parse_joint(el)
        except (ValueError, TypeError, AttributeError, KeyError, IndexError) as exc:
            raise src.fail(f"joint {name!r}: cannot read it: {exc}", el.sourceline, f"joint {name}") from None
    return links, joints, parsed


# XML Schema 1.1 Part 2 §3.3.5 double, the type URDF's numbers are (xs:double; whitespace
# collapsed, lists split at XML whitespace): Python's float() also took '1_0' (as 10), 'inf',
# 'nan', 'infinity' and digits of other scripts.
_XS_DOUBLE = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|[+-]?INF|NaN")
_XML_SPACE = re.compile(r"[ \t\n\r]+")


def xs_doubles(text: str) -> list[float]:
    """The numbers of an attribute holding xs:double values; ValueError naming one that is not."""
    out = []
    for token in _XML_SPACE.split(text.strip(" \t\n\r")) if text.strip(" \t\n\r") else []:
        if not _XS_DOUBLE.fullmatch(token):
            raise ValueError(f"{token[:40]!r} is not a number (XML Schema double: digits 0-9, an optional "
                             f"sign, point and exponent)")
        out.append(float(token))
    return out


_NUMBER_ATTRIBUTES = {   # those of a joint's elements (URDF's XSD: urdf.xsd), whoever reads them
    "origin": ("xyz", "rpy"), "axis": ("xyz",), "limit": ("lower", "upper", "effort", "velocity"),
    "dynamics": ("damping", "friction"), "mimic": ("multiplier", "offset"),
    "calibration": ("rising", "falling"),
    "safety_controller": ("soft_lower_limit", "soft_upper_limit", "k_position", "k_velocity")}


def _joint_numbers(src: _Source, el, name: str) -> None:
    """Every number of the joint written as an xs:double, refused at its line before yourdfpy
    (which reads them with float() and names no line) sees them."""
    for part, attrs in _NUMBER_ATTRIBUTES.items():
        sub = el.find(part)
        for attr in attrs:
            if sub is not None and sub.get(attr) is not None:
                try:
                    xs_doubles(sub.get(attr))
                except ValueError as exc:
                    raise src.fail(f"joint {name!r} {part} {attr}: {exc}", sub.sourceline,
                                   f"joint {name}.{part}.{attr}") from None


def _finite(src: _Source, values, what: str, line: int, fld: str, count: int = 3) -> tuple:
    values = tuple(float(v) for v in values)
    if len(values) != count:
        raise src.fail(f"{what}: expected {count} numbers, got {len(values)}", line, fld)
    for v in values:
        if not math.isfinite(v):
            raise src.fail(f"{what}: {v!r} is not a finite number", line, fld)
        if abs(v) > MAX_LITERAL / 1000:
            raise src.fail(f"{what}: {v!r} is beyond {MAX_LITERAL / 1000:g} in magnitude", line, fld)
        if 0 < abs(v) < MIN_MAGNITUDE:   # the machine format's numbers (in mm) stop at 1e-30
            raise src.fail(f"{what}: {v!r} is below {MIN_MAGNITUDE:g} in magnitude (write 0)", line, fld)
    return values


def _attribute_numbers(src: _Source, el, attr: str, default: str, what: str, fld: str) -> tuple:
    text = el.get(attr, default) if el is not None else default
    try:
        return _finite(src, xs_doubles(text), what, el.sourceline, fld)
    except ValueError as exc:
        raise src.fail(f"{what}: {exc}", el.sourceline, fld) from None


def _origin_numbers(src: _Source, el, name: str) -> tuple[tuple, tuple]:
    """xyz (m) and rpy (rad) of a joint's <origin>, as written (yourdfpy keeps only their matrix)."""
    origin = el.find("origin")
    if origin is None:
        return (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
    return tuple(_attribute_numbers(src, origin, k, "0 0 0", f"joint {name!r} origin {k}", f"joint {name}.origin.{k}")
                 for k in ("xyz", "rpy"))


def sanitise(name: str) -> str:
    """A URDF name under the machine format's NAME rule: letters, digits and '_', starting
    with a letter, not a reserved word."""
    out = re.sub(r"[^A-Za-z0-9_]", "_", name)
    if not out or not out[0].isalpha() or not out[0].isascii():
        out = "j_" + out
    return out + "_" if out in RESERVED else out


# The measured coordinates' column names (chaincomp.measure.table.COLUMNS): an axis of one of these
# names would make a measurements file's column mean both, which identify refuses.
MEASURED_NAMES = ("x", "y", "z", "kx", "ky", "kz", "qw", "qx", "qy", "qz")


def axis_name(joint: str) -> str:
    """A moving joint's symbol: sanitised, and 'x' -> 'x_' as a reserved word is renamed."""
    out = sanitise(joint)
    return out + "_" if out in MEASURED_NAMES else out


def kinematic_path(path: str, base: str, tip: str) -> tuple[str, list[PathJoint], str]:
    """The robot's name and the joints from link ``base`` down to link ``tip``, checked."""
    src = _Source(path, read_text(path))
    root = _parse_xml(src)
    links, joint_el, joints = _read_model(src, root)
    robot_line = root.sourceline
    for which, link in (("--base", base), ("--tip", tip)):
        if link not in links:
            shown = ", ".join(sorted(links)[:12]) + (", ..." if len(links) > 12 else "")
            raise src.fail(f"{which} {link!r}: no link of that name (links: {shown or 'none'})", robot_line)
    parent_joint: dict = {}
    for name, j in joints.items():
        if j.child in parent_joint:   # a tree gives every link one parent: two close a loop
            first = parent_joint[j.child]
            raise src.fail(f"link {j.child!r} is the child of joints {first!r} (line "
                           f"{joint_el[first].sourceline}) and {name!r}: a closed loop, which a URDF tree "
                           "cannot hold", joint_el[name].sourceline, f"joint {name}.child")
        parent_joint[j.child] = name
    names, link, passed = [], tip, [tip]   # the joints and links going up from --tip
    while link != base and link in parent_joint:
        names.append(parent_joint[link])
        link = joints[parent_joint[link]].parent
        if link in passed:
            raise src.fail(f"the joints above link {tip!r} form a cycle through link {link!r}",
                           joint_el[names[-1]].sourceline, f"joint {names[-1]}")
        passed.append(link)
    up: list[str] = []
    if link != base:
        # --base may hang off the path by fixed joints (UR's controller frame 'base', a sibling
        # of the chain under base_link): walked up to the path, each by its origin's inverse
        at = base
        while at not in passed:
            name = parent_joint.get(at)
            if name is None or joints[name].type != "fixed" or name in up:
                why = "" if name is None or name in up else \
                    f", and {base!r} hangs from it by the {joints[name].type} joint {name!r} (only fixed joints may)"
                raise src.fail(f"--tip {tip!r} is not below --base {base!r}: going up from {tip!r} the tree ends "
                               f"at {link!r}{why}", links[tip].sourceline, f"link {tip}")
            up.append(name)
            at = joints[name].parent
        names = names[:passed.index(at)]
    if not names and not up:
        raise src.fail(f"--base and --tip are the same link {base!r}: no joint between them", robot_line)
    # a tree has a root: going up from --base must end at a link that no joint moves, not come
    # back round (a cycle through --base would make every link of it its own ancestor)
    link, above = base, {base}
    while link in parent_joint:
        name = parent_joint[link]
        link = joints[name].parent
        if link in above:
            first = parent_joint[base]
            raise src.fail(f"--base {base!r} is the child of joint {first!r}, and the joints above it come back "
                           f"round to link {link!r} (through joint {name!r}, line {joint_el[name].sourceline}): a "
                           "cycle, which a URDF tree cannot hold", joint_el[first].sourceline, f"joint {first}.child")
        above.add(link)
    out = [dataclasses.replace(_path_joint(src, joints[n], joint_el[n]), inverted=True) for n in up]
    out += [_path_joint(src, joints[n], joint_el[n]) for n in reversed(names)]
    return root.get("name") or "robot", out, src.text


def _path_joint(src: _Source, j, el) -> PathJoint:
    fld = f"joint {j.name}"
    line = el.sourceline
    if j.type in ("floating", "planar"):
        raise src.fail(f"joint {j.name!r} is {j.type}: only revolute, continuous, prismatic and fixed joints "
                       "form a machine's chain (a floating base is a 6-DOF error block or a fixed origin)",
                       line, f"{fld}.type")
    if j.type not in MOVING + ("fixed",):
        raise src.fail(f"joint {j.name!r} has type {j.type!r} (expected revolute, continuous, prismatic or "
                       "fixed)", line, f"{fld}.type")
    if j.mimic is not None:
        mline = el.find("mimic").sourceline
        raise src.fail(f"joint {j.name!r} mimics joint {j.mimic.joint!r}: mimic joints are not supported "
                       "(the machine format has one independent symbol per axis)", mline, f"{fld}.mimic")
    xyz, rpy = _origin_numbers(src, el, j.name)
    axis, limits = (0.0, 0.0, 1.0), None
    if j.type in MOVING:
        aline = el.find("axis").sourceline if el.find("axis") is not None else line
        axis = _finite(src, j.axis, f"joint {j.name!r} axis", aline, f"{fld}.axis")
        if math.sqrt(sum(a * a for a in axis)) < 1e-9:
            raise src.fail(f"joint {j.name!r}: its axis {list(axis)} is zero", aline, f"{fld}.axis")
        limits = _limits(src, j, el)
    return PathJoint(j.name, axis_name(j.name) if j.type in MOVING else "", j.type, line, xyz, rpy, axis, limits)


def _limits(src: _Source, j, el) -> tuple:
    if j.type == "continuous":
        return (-CONTINUOUS_LIMIT_DEG, CONTINUOUS_LIMIT_DEG)
    lim = el.find("limit")
    fld = f"joint {j.name}.limit"
    if lim is None:
        raise src.fail(f"joint {j.name!r} ({j.type}) has no <limit lower=... upper=...>", el.sourceline, fld)
    try:
        lo, hi = _finite(src, (j.limit.lower or 0.0, j.limit.upper or 0.0), f"joint {j.name!r} limit",
                         lim.sourceline, fld, 2)
    except (TypeError, ValueError) as exc:
        raise src.fail(f"joint {j.name!r} limit: {exc}", lim.sourceline, fld) from None
    if not lo < hi:
        raise src.fail(f"joint {j.name!r}: lower limit {lo!r} is not below upper limit {hi!r}", lim.sourceline, fld)
    if j.type == "revolute":
        # rounded to 1e-9 deg: 2*pi written as 6.28318530718 is 360 deg, not 360.0000000000237
        return (round(math.degrees(lo), 9), round(math.degrees(hi), 9))
    return tuple(float(Decimal(repr(v)) * 1000) for v in (lo, hi))


# ----------------------------------------------------------------------------- writing

def _decimal(value: float, scale: int = 1) -> str:
    """``value`` (a float, as Python's shortest repr writes it) times ``scale``, exactly, as
    a decimal the expression parser reads as the same rational."""
    d = (Decimal(repr(value)) * scale).normalize()
    if d == 0:
        return "0"
    text = format(d, "f")
    return text if len(text) <= 32 else format(d, "e")


def _flow(expr: str) -> str:
    """An expression as a YAML flow scalar: quoted where a comma or bracket would end it."""
    return yaml_scalar(expr) if re.search(r"[,()\[\]{}:#]", expr) else expr


def _aligned(axis: tuple) -> tuple[str, int] | None:
    """('x'|'y'|'z', +1|-1) where the axis lies along a coordinate axis."""
    nonzero = [i for i, a in enumerate(axis) if a != 0.0]
    if len(nonzero) != 1:
        return None
    return "xyz"[nonzero[0]], 1 if axis[nonzero[0]] > 0 else -1


def _motion(j: PathJoint, motion: str) -> list[str]:
    """Chain elements moving the joint by ``motion`` (an expression in internal units)."""
    label = f"label: {yaml_scalar('joint ' + j.name)}"
    along = _aligned(j.axis)
    if j.type == "prismatic":
        if along:
            vec = ["0", "0", "0"]
            vec["xyz".index(along[0])] = motion if along[1] > 0 else f"-({motion})"
        else:
            norm = sum(a * a for a in j.axis)
            div = "" if norm == 1.0 else "/sqrt(" + " + ".join(f"({_decimal(a)})^2" for a in j.axis) + ")"
            vec = [f"({motion})*({_decimal(a)}){div}" if a else "0" for a in j.axis]
        return [f"{{translate: [{', '.join(_flow(v) for v in vec)}], {label}}}"]
    if along:
        angle = motion if along[1] > 0 else f"-({motion})"
        return [f"{{rotate: {along[0]}, angle: {_flow(angle)}, {label}}}"]
    ux, uy, uz = (_decimal(a) for a in j.axis)
    phi = f"atan2({uy}, {ux})"
    theta = f"atan2(sqrt(({ux})^2 + ({uy})^2), {uz})"
    frame = f"label: {yaml_scalar('joint ' + j.name + ' axis frame')}"
    return [f"{{rotate: z, angle: {_flow(phi)}, {frame}}}", f"{{rotate: y, angle: {_flow(theta)}}}",
            f"{{rotate: z, angle: {_flow(motion)}, {label}}}",
            f"{{rotate: y, angle: {_flow('-' + theta)}}}", f"{{rotate: z, angle: {_flow('-' + phi)}}}"]


def _origin(j: PathJoint) -> list[str]:
    if j.inverted:   # (T(xyz)·Rz(yaw)·Ry(pitch)·Rx(roll))^-1 = Rx(-roll)·Ry(-pitch)·Rz(-yaw)·T(-xyz)
        label = f", label: {yaml_scalar(j.name + ' origin, inverted')}"
        out = []
        for axis, angle in zip("xyz", j.rpy):
            if angle:
                out.append(f"{{rotate: {axis}, angle: {_decimal(-angle)}{label}}}")
                label = ""
        if any(j.xyz):
            out.append(f"{{translate: [{', '.join(_decimal(-v, 1000) for v in j.xyz)}]{label}}}")
        return out
    label = f", label: {yaml_scalar(j.name + ' origin')}"
    out = []
    if any(j.xyz):
        out.append(f"{{translate: [{', '.join(_decimal(v, 1000) for v in j.xyz)}]{label}}}")
        label = ""
    roll, pitch, yaw = j.rpy
    for axis, angle in (("z", yaw), ("y", pitch), ("x", roll)):
        if angle:
            out.append(f"{{rotate: {axis}, angle: {_decimal(angle)}{label}}}")
            label = ""
    return out


def shown_path(path: str) -> str:
    """The URDF's path as the header writes it: as given, but an absolute path below the current
    folder relative to it (the file travels; the user's home folder need not travel with it)."""
    if os.path.isabs(path):
        relative = os.path.relpath(path)
        if relative != os.pardir and not relative.startswith(os.pardir + os.sep):
            return relative
    return path


def error_modes(errors: str) -> tuple[str, tuple[str, ...]]:
    """'origins,tool,base' -> ('origins', ('tool', 'base')): one of ERROR_MODES (none if only
    blocks are given) and the ERROR_BLOCKS, each at most once."""
    items = [t.strip() for t in errors.split(",")]
    modes = [t for t in items if t in ERROR_MODES]
    blocks = tuple(b for b in ERROR_BLOCKS if b in items)
    unknown = [t for t in items if t not in ERROR_MODES + ERROR_BLOCKS]
    if unknown or len(modes) > 1 or len(modes) + len(blocks) != len(items):
        why = (f"{unknown[0]!r} is none of {', '.join(ERROR_MODES + ERROR_BLOCKS)}" if unknown else
               f"one of {', '.join(ERROR_MODES)} at most" if len(modes) > 1 else "each item once")
        raise ChaincompError(f"--errors {errors!r}: {why} (e.g. --errors origins,tool,base)")
    return (modes[0] if modes else "none"), blocks


def _block_symbols(block: str) -> list[str]:
    """The six symbol entries of the tool or base block."""
    out = []
    for k in _BLOCK:
        unit = "um" if k[0] == "d" else "arcsec"
        axis = {"d": "along ", "e": "about "}[k[0]] + k[1]
        if block == "base":
            meaning = f"registration: the base in the measuring instrument's frame, {axis} (not a machine error)"
            out.append(f"  - {{name: base_{k}, role: error, unit: {unit}, registration: true, "
                       f"meaning: {yaml_scalar(meaning)}}}")
        else:
            meaning = f"tool mount error {axis} (in the tip link's frame)"
            out.append(f"  - {{name: tool_{k}, role: error, unit: {unit}, meaning: {yaml_scalar(meaning)}}}")
    return out


def machine_text(urdf_path: str, base: str, tip: str, errors: str = "none", tool_point=(0.0, 0.0, 0.0),
                 tool_direction=(0.0, 0.0, 1.0), name: str | None = None, version: str = "",
                 tool_reference=None) -> str:
    """The machine file (YAML text) of the path base -> tip of the URDF; with ``tool_reference``
    a six-DOF tool frame (its x axis the reference's part orthogonal to the direction)."""
    mode, extra = error_modes(errors)
    errors = ",".join((mode,) + extra) if mode != "none" or not extra else ",".join(extra)
    robot, joints, _ = kinematic_path(urdf_path, base, tip)
    src = _Source(urdf_path, "")
    machine_name = name or sanitise(robot)
    if not NAME.match(machine_name) or machine_name in RESERVED:
        raise ChaincompError(f"--name {machine_name!r}: a machine name is an identifier (letters, digits, '_', "
                             "starting with a letter) and not a reserved word")
    moving = [j for j in joints if j.type in MOVING]
    if not moving:
        raise src.fail(f"no revolute, continuous or prismatic joint between {base!r} and {tip!r}: nothing moves",
                       joints[0].line)
    offsets, blocks = mode in ("joint-offsets", "all"), mode in ("origins", "all")

    symbols: list[str] = []
    taken: dict[str, PathJoint | None] = {}   # None: a tool or base block's

    def declare(symbol: str, j: PathJoint, entry: str) -> None:
        if symbol in taken:
            other = taken[symbol]
            if other is None:
                raise src.fail(f"joint {j.name!r} gives the name {symbol!r}, which --errors {symbol[:4]} "
                               "declares for its block; rename the joint in the URDF", j.line, f"joint {j.name}")
            raise src.fail(f"joints {other.name!r} (line {other.line}) and {j.name!r} both give the name "
                           f"{symbol!r} in the machine file; rename one of them in the URDF", j.line,
                           f"joint {j.name}")
        taken[symbol] = j
        symbols.append(entry)

    taken.update({f"{block}_{k}": None for block in extra for k in _BLOCK})

    for j in moving:
        unit = "mm" if j.type == "prismatic" else "deg"
        lo, hi = j.limits
        meaning = f"URDF joint {j.name} ({j.type})"
        declare(j.axis_name, j, f"  - {{name: {j.axis_name}, role: axis, unit: {unit}, limits: [{lo!r}, {hi!r}], "
                                f"meaning: {yaml_scalar(meaning)}}}")
    for j in moving:
        if offsets:
            unit = "um" if j.type == "prismatic" else "arcsec"
            declare(f"{j.axis_name}_zero", j, f"  - {{name: {j.axis_name}_zero, role: error, unit: {unit}, "
                                              f"meaning: {yaml_scalar('zero offset of joint ' + j.name)}}}")
        if blocks:
            for k in _BLOCK:
                unit = "um" if k[0] == "d" else "arcsec"
                what = {"d": "origin error along ", "e": "origin error about "}[k[0]] + k[1]
                declare(f"{j.axis_name}_{k}", j, f"  - {{name: {j.axis_name}_{k}, role: error, unit: {unit}, "
                                                 f"meaning: {yaml_scalar(what + ' of joint ' + j.name)}}}")

    for block in extra:
        symbols += _block_symbols(block)
    chain: list[str] = []
    if "base" in extra:
        chain.append("{errors: {" + ", ".join(f"{k}: base_{k}" for k in _BLOCK) + "}, order: txyz, "
                     "label: base registration}")
    for j in joints:
        chain += _origin(j)
        if j.type not in MOVING:
            continue
        if blocks:
            chain.append("{errors: {" + ", ".join(f"{k}: {j.axis_name}_{k}" for k in _BLOCK) + "}, order: txyz, "
                         f"label: {yaml_scalar(j.name + ' origin errors')}}}")
        chain += _motion(j, f"{j.axis_name} + {j.axis_name}_zero" if offsets else j.axis_name)
    if "tool" in extra:
        chain.append("{errors: {" + ", ".join(f"{k}: tool_{k}" for k in _BLOCK) + "}, order: txyz, "
                     "label: tool mount errors}")
    if len(symbols) > MAX_SYMBOLS or len(chain) > MAX_CHAIN_ELEMENTS:
        raise src.fail(f"the path {base} -> {tip} makes {len(symbols)} symbols and {len(chain)} chain elements "
                       f"with --errors {errors} (a machine file holds at most {MAX_SYMBOLS} and "
                       f"{MAX_CHAIN_ELEMENTS})", joints[0].line)

    header = [
        f"# Imported from the URDF {one_line(shown_path(urdf_path))} by chaincomp {version} import-urdf",
        f"# robot {one_line(robot)}, path {one_line(base)} -> {one_line(tip)}: "
        + ", ".join(f"{one_line(j.name)} ({j.type}{', inverted' if j.inverted else ''})" for j in joints),
        f"# errors: {errors}. Lengths in mm (the URDF's metres x 1000, exactly), angles in rad as written;",
        "# revolute limits converted from rad to deg, continuous joints limited to [-360, 360] deg.",
        "# The tool point, direction" + (" and reference" if tool_reference is not None else "")
        + " are in the frame of the tip link.",
    ]
    renamed = [j for j in moving if j.axis_name != j.name]
    if renamed:
        header += ["# Joints renamed for the machine format (letters, digits and '_'; no reserved word; not x, y, z,",
                   "# kx, ky, kz, the measured coordinates' names): "
                   + ", ".join(f"{one_line(j.name)} -> {j.axis_name}" for j in renamed)]
    desc = f"{robot} from URDF, {base} -> {tip}"
    lines = header + [
        f"name: {machine_name}",
        f"description: {yaml_scalar(desc)}",
        "length_unit: mm",
        "rotation_sense: right_hand",
        "error_block_order: txyz",
        "",
        "symbols:",
        *symbols,
        "",
        "chain:",
        *(f"  - {c}" for c in chain),
        "",
        "tool:",
        f"  point: [{', '.join(repr(float(v)) for v in tool_point)}]",
        f"  direction: [{', '.join(repr(float(v)) for v in tool_direction)}]",
    ]
    if tool_reference is not None:
        lines.append(f"  reference: [{', '.join(repr(float(v)) for v in tool_reference)}]")
    return "\n".join(lines) + "\n"
