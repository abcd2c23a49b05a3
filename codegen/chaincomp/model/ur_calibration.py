"""Universal Robots' kinematics calibration file: read in as errors, written out from them.

The format (UniversalRobots/Universal_Robots_ROS2_Description, config/ur5e/default_kinematics.yaml;
the ROS 1 ur_description and ur_calibration's output are the same):

    kinematics:
      shoulder:  {x: 0, y: 0, z: 0.1625, roll: 0, pitch: 0, yaw: 0}
      upper_arm: {...}   forearm: {...}   wrist_1: {...}   wrist_2: {...}   wrist_3: {...}
      hash: calib_12788084448423163542

urdf/inc/ur_common.xacro (read_model_data) reads each entry and urdf/ur_macro.xacro writes it,
as text, into the <origin xyz="x y z" rpy="roll pitch yaw"> of shoulder_pan_joint,
shoulder_lift_joint, elbow_joint, wrist_1_joint, wrist_2_joint and wrist_3_joint, each turning
about its own z (<axis xyz="0 0 1"/>), metres and radians, R = Rz(yaw)·Ry(pitch)·Rx(roll) (URDF).
So the six entries are the origins of the six moving joints of the path, in order, whatever
their names (a tf_prefix changes them). The hash is the controller's checksum of its own
calibration: UR's driver compares it with the robot's and logs an error when they differ
(Universal_Robots_Client_Library, src/ur/calibration_checker.cpp).

Reading: a machine imported from such a URDF with --errors origins (or all) has, per moving
joint J, the block B = T(J_dx, J_dy, J_dz)·Rx(J_ex)·Ry(J_ey)·Rz(J_ez) after the URDF's origin N;
a calibrated origin C is N·B, so B = N⁻¹·C, taken apart exactly (no small-angle step).
Writing: each joint's calibrated origin (urdf_out.calibrated_origin) as x y z roll pitch yaw.
"""

from __future__ import annotations

import hashlib
import math

import numpy as np

from ..errors import ChaincompError
from ..escape import one_line
from .urdf import MOVING, PathJoint, xs_doubles
from .urdf_out import _frame, _rot, _rpy, calibrated_origin
from .yamlsource import describe, line_of, load_yaml

SEGMENTS = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")
KEYS = ("x", "y", "z", "roll", "pitch", "yaw")
MAX_METRES = 10.0   # an arm's joint origin is within a few metres; beyond, it is not this format


def ur_joints(joints: list[PathJoint], what: str) -> list[PathJoint]:
    """The six moving joints of the path, each turning about +z, as ur_macro.xacro writes
    them; refused otherwise (a URDF of another form holds other origins)."""
    moving = [j for j in joints if j.type in MOVING]
    wrong = [j for j in moving if j.type == "prismatic" or tuple(j.axis) != (0.0, 0.0, 1.0)]
    if len(moving) != 6 or wrong:
        why = (f"{len(moving)} moving joints" if len(moving) != 6 else
               f"joint {wrong[0].name!r} is {wrong[0].type} about {list(wrong[0].axis)}")
        raise ChaincompError(f"{what}: UR's kinematics file holds the origins of six revolute joints each turning "
                             f"about its z (<axis xyz=\"0 0 1\"/>, as ur_description's ur_macro.xacro writes them); "
                             f"this path has {why}")
    return moving


def read(path: str) -> tuple[list[np.ndarray], str]:
    """The six origins (4x4, metres) in SEGMENTS order and the hash, from a UR calibration file."""
    doc = load_yaml(path)
    top = doc.get("kinematics") if isinstance(doc, dict) else None
    if not isinstance(top, dict):
        raise ChaincompError("expected a mapping 'kinematics:' (UR's kinematics calibration file)", path,
                             line_of(doc, "kinematics", 1), "kinematics")
    for key in top:
        if key not in SEGMENTS + ("hash",):
            raise ChaincompError(f"unknown entry {key!r} (expected {', '.join(SEGMENTS)}, hash)", path,
                                 line_of(top, key), f"kinematics.{key}")
    origins = []
    for seg in SEGMENTS:
        node = top.get(seg)
        if not isinstance(node, dict):
            raise ChaincompError(f"expected a mapping of {', '.join(KEYS)}, got {describe(node)}", path,
                                 line_of(top, seg, line_of(top)), f"kinematics.{seg}")
        values = []
        for key in KEYS:
            fld, line = f"kinematics.{seg}.{key}", line_of(node, key, line_of(node))
            if key not in node:
                raise ChaincompError(f"missing {key!r}", path, line, fld)
            raw = node[key]
            number = _number_of(raw)
            if number is None or not math.isfinite(number):
                raise ChaincompError(f"expected a finite number, got {describe(raw)}", path, line, fld)
            limit, unit = (MAX_METRES, "m") if key in "xyz" else (4 * math.pi, "rad")
            if abs(number) > limit:
                raise ChaincompError(f"{number!r} is beyond {limit:g} {unit} in magnitude", path, line, fld)
            values.append(number)
        x, y, z, roll, pitch, yaw = values
        origins.append(_frame((x, y, z), _rot("z", yaw) @ _rot("y", pitch) @ _rot("x", roll)))
    digest = top.get("hash", "")
    if not isinstance(digest, str):
        raise ChaincompError(f"expected text, got {describe(digest)}", path, line_of(top, "hash"), "kinematics.hash")
    return origins, digest


def _number_of(raw) -> float | None:
    """A YAML number, or text that is one: xacro puts the value's text into the URDF attribute,
    which URDF readers take as an xs:double (so '1e-05', text to YAML 1.1, is the number)."""
    if isinstance(raw, str):
        try:
            found = xs_doubles(raw)
        except ValueError:
            return None
        return found[0] if len(found) == 1 else None
    return float(raw) if isinstance(raw, (int, float)) and not isinstance(raw, bool) else None


def _xyz_angles(r: np.ndarray) -> tuple[float, float, float]:
    """a, b, c with r = Rx(a)·Ry(b)·Rz(c), the order of an error block's rotations."""
    b = math.atan2(r[0, 2], math.hypot(r[0, 0], r[0, 1]))
    return math.atan2(-r[1, 2], r[2, 2]), b, math.atan2(-r[0, 1], r[0, 0])


def errors_from(joints: list[PathJoint], origins: list[np.ndarray], machine, what: str) -> dict[str, float]:
    """The origin blocks' values (internal units: mm, rad) that make each joint's origin the
    calibrated one: B = N⁻¹·C; every other error of the machine zero."""
    names = {s.name for s in machine.errors}
    missing = [f"{j.axis_name}_{k}" for j in joints for k in ("dx", "dy", "dz", "ex", "ey", "ez")
               if f"{j.axis_name}_{k}" not in names]
    if missing:
        raise ChaincompError(f"{what}: the machine has no error {missing[0]}: a calibration moves every joint "
                             f"origin, import the URDF with --errors origins (or all)", machine.file)
    out = {s.name: 0.0 for s in machine.errors}
    for j, calibrated in zip(joints, origins):
        nominal = calibrated_origin(j, {})
        block = np.linalg.solve(nominal, calibrated)
        d = block[:3, 3] * 1000.0
        a, b, c = _xyz_angles(block[:3, :3])
        out.update({f"{j.axis_name}_{k}": float(v) for k, v in zip(("dx", "dy", "dz", "ex", "ey", "ez"),
                                                                   (*d, a, b, c))})
    return out


def _number(v: float) -> str:
    text = repr(float(v))
    return "0" if text in ("0.0", "-0.0") else text


def text(joints: list[PathJoint], values: dict[str, float], source: str) -> str:
    """UR's kinematics file of the six joints with their errors folded into their origins."""
    lines = ["kinematics:"]
    for seg, j in zip(SEGMENTS, joints):
        m = calibrated_origin(j, values)
        roll, pitch, yaw = _rpy(m[:3, :3])
        lines.append(f"  {seg}:")
        lines += [f"    {k}: {_number(v)}" for k, v in zip(KEYS, (*m[:3, 3], roll, pitch, yaw))]
    # not the controller's checksum (this calibration is not the controller's): the driver says they differ
    digest = hashlib.sha256("\n".join(lines).encode()).hexdigest()[:16]
    return (f"# UR kinematics calibration written by chaincomp export-urdf from {one_line(source)}: the origins of "
            "the six joints (ur_description's ur_macro.xacro reads them).\n"
            "# The hash is chaincomp's, not the controller's checksum: UR's driver will log that they differ.\n"
            + "\n".join(lines) + f"\n  hash: chaincomp_{digest}\n")
