"""A calibrated URDF: the URDF a machine file was imported from (model/urdf.py), with each
moving joint's identified errors folded into its <origin>, so that a robot stack reading URDF
(ROS, MoveIt, Pinocchio) gets the calibrated kinematics.

The import puts, per moving joint J (--errors origins / joint-offsets / all), the block
B = T(J_dx, J_dy, J_dz)·Rx(J_ex)·Ry(J_ey)·Rz(J_ez) after the joint's origin and J_zero inside its
motion: origin·B·M(q + J_zero). A motion about (or along) the joint's own axis u through the
origin's point splits, M(q + z) = M(z)·M(q), so the calibrated origin is origin·B·M(J_zero) and
the joint keeps its axis, type and limits (URDF, http://wiki.ros.org/urdf/XML/joint: <origin
xyz rpy>, R = Rz(yaw)·Ry(pitch)·Rx(roll), metres and radians). Everything else in the file is
kept as written (comments too); the new numbers are written with 17 significant digits.
"""

from __future__ import annotations

import math

import numpy as np

from .machine import ROT_PLANE
from .urdf import MOVING, PathJoint, kinematic_path


def _rot(axis: str, a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    i, j = ROT_PLANE[axis]   # the plane it turns, in its positive sense (as the models do)
    r = np.eye(3)
    r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
    return r


def _about(u, a: float) -> np.ndarray:
    """Rotation by ``a`` about the unit vector ``u`` (Rodrigues)."""
    u = np.asarray(u, float) / np.linalg.norm(u)
    k = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
    return np.eye(3) + math.sin(a) * k + (1 - math.cos(a)) * (k @ k)


def _frame(xyz, r) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = r, xyz
    return m


def _rpy(r: np.ndarray) -> tuple[float, float, float]:
    """roll, pitch, yaw with r = Rz(yaw)·Ry(pitch)·Rx(roll)."""
    pitch = math.atan2(-r[2, 0], math.hypot(r[0, 0], r[1, 0]))
    if math.hypot(r[0, 0], r[1, 0]) < 1e-12:   # pitch at +-90 deg: roll and yaw share one axis
        return math.atan2(-r[1, 2], r[1, 1]), pitch, 0.0
    return math.atan2(r[2, 1], r[2, 2]), pitch, math.atan2(r[1, 0], r[0, 0])


def calibrated_origin(j: PathJoint, values: dict[str, float]) -> np.ndarray:
    """The joint's origin with its errors folded in (metres, a 4x4), ``values`` in internal
    units (mm, rad) by symbol name; errors the file does not give are zero."""
    roll, pitch, yaw = j.rpy
    origin = _frame(j.xyz, _rot("z", yaw) @ _rot("y", pitch) @ _rot("x", roll))
    get = lambda k: values.get(f"{j.axis_name}_{k}", 0.0)  # noqa: E731
    d = np.array([get("dx"), get("dy"), get("dz")]) / 1000.0
    block = _frame(d, _rot("x", get("ex")) @ _rot("y", get("ey")) @ _rot("z", get("ez")))
    u = np.asarray(j.axis, float) / np.linalg.norm(j.axis)
    zero = get("zero")
    motion = _frame(u * zero / 1000.0, np.eye(3)) if j.type == "prismatic" else _frame(np.zeros(3), _about(u, zero))
    return origin @ block @ motion


def _number(v: float) -> str:
    text = repr(float(v))
    return "0" if text in ("0.0", "-0.0") else text


def calibrated_urdf(urdf_path: str, base: str, tip: str, values: dict[str, float]) -> bytes:
    """The URDF's text with every moving joint of the path base -> tip given its calibrated
    <origin> (``values``: internal units by symbol name, e.g. params.values)."""
    _, joints, text = kinematic_path(urdf_path, base, tip)   # checked and hardened as import-urdf reads it
    return with_origins(text, {j.name: calibrated_origin(j, values) for j in joints if j.type in MOVING})


def with_origins(text: str, origins: dict[str, np.ndarray]) -> bytes:
    """The URDF ``text`` (as kinematic_path returns it, checked) with these joints' <origin> set
    to these frames (4x4, metres), the rest kept as written."""
    from lxml import etree
    # the same settings as urdf._parse_xml (no DTD, entities, network), comments kept
    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False, huge_tree=False)
    root = etree.fromstring(text.encode("utf-8"), parser=parser)
    by_name = {el.get("name"): el for el in root.findall("joint")}
    for name, m in origins.items():
        el = by_name[name]
        origin = el.find("origin")
        if origin is None:
            origin = etree.SubElement(el, "origin")
        origin.set("xyz", " ".join(_number(v) for v in m[:3, 3]))
        origin.set("rpy", " ".join(_number(v) for v in _rpy(m[:3, :3])))
    return etree.tostring(root.getroottree(), xml_declaration=True, encoding="utf-8") + b"\n"
