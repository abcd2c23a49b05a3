"""vmc_xyz and trunnion_ac rebuilt in numpy from the standards' definitions, without chaincomp's
chain or parser (plain numpy; never import chaincomp here): the table's error motion as the
matrix inverse of the ISO 230-1 error block (the standard's errors are the tool's relative to
the workpiece), squareness as a rotation of an axis' direction of travel, a rotary axis as a
Rodrigues rotation about its actual axis line (ISO 230-7 location errors: a point and a
direction). The tool relative to the workpiece is inv(W)·T. Internal units (mm, rad)."""

import math

import numpy as np


def trans(x, y, z):
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def rot(axis, angle):
    """Right-handed rotation about the x, y or z axis."""
    c, s = math.cos(angle), math.sin(angle)
    i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
    m = np.eye(4)
    m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
    return m


def iso_block(d, e):
    """ISO 230-1 error motion of an axis, tool relative to workpiece: T(d)·Rx·Ry·Rz."""
    return trans(*d) @ rot("x", e[0]) @ rot("y", e[1]) @ rot("z", e[2])


def rot_line(point, u, angle):
    """Rotation by ``angle`` (right-handed) about the line through ``point`` along ``u``
    (Rodrigues' formula)."""
    u = np.asarray(u, float) / np.linalg.norm(u)
    k = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
    r = np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k
    m = np.eye(4)
    m[:3, :3] = r
    m[:3, 3] = np.asarray(point) - r @ np.asarray(point)
    return m


def pose(w, t):
    """Tool point and direction (tool axis +z of the tool frame) relative to the workpiece."""
    rel = np.linalg.inv(w) @ t
    return rel[:3, 3], rel[:3, :3] @ np.array([0.0, 0.0, 1.0])


def vmc_pose(v):
    """Table X on saddle Y (workpiece branch), head Z (tool branch); internal units."""
    g = lambda *names: [v.get(n, 0.0) for n in names]  # noqa: E731
    # directions of travel the tool sees, tilted by squareness (X is the reference)
    y_dir = rot("z", v.get("EC0Y", 0.0))[:3, :3] @ [0, 1, 0]
    z_dir = (rot("y", v.get("EB0Z", 0.0)) @ rot("x", v.get("EA0Z", 0.0)))[:3, :3] @ [0, 0, 1]
    e_x = iso_block(g("EXX", "EYX", "EZX"), g("EAX", "EBX", "ECX"))
    e_y = iso_block(g("EXY", "EYY", "EZY"), g("EAY", "EBY", "ECY"))
    e_z = iso_block(g("EXZ", "EYZ", "EZZ"), g("EAZ", "EBZ", "ECZ"))
    # a table's own motion is the inverse of what the tool sees: it moves by minus the
    # travel, with the inverse error motion
    saddle = np.linalg.inv(trans(*(v["Y"] * y_dir)) @ e_y)
    table = np.linalg.inv(trans(v["X"], 0, 0) @ e_x)
    w = saddle @ table @ trans(0, 0, v["hT"])
    t = trans(0, 0, v["H"]) @ trans(*(v["Z"] * z_dir)) @ e_z @ trans(0, 0, -v["L"])
    return pose(w, t)


def trunnion_pose(v):
    """A tilting table carrying C; head X, Y, Z perfect. +A, +C turn the tool relative to
    the workpiece, so each table turns by minus its angle (plus its zero error)."""
    g = lambda n: v.get(n, 0.0)  # noqa: E731
    u_a = (rot("y", g("EB0A")) @ rot("z", g("EC0A")))[:3, :3] @ [1, 0, 0]
    u_c = (rot("x", g("EA0C")) @ rot("y", g("EB0C")))[:3, :3] @ [0, 0, 1]
    w = (rot_line([0, g("EY0A"), g("EZ0A")], u_a, -(v["A"] + g("EA0A")))
         @ rot_line([g("EX0C"), g("EY0C"), 0], u_c, -(v["C"] + g("EC0C")))
         @ trans(0, 0, v["hC"]))
    t = trans(v["X"], v["Y"], v["H"] + v["Z"] - v["L"])
    return pose(w, t)


MODELS = {"vmc_xyz": vmc_pose, "trunnion_ac": trunnion_pose}
