"""Universal Robots' ROS 2 description in numpy and text, written here from its source: the truth
the UR calibration tests compare chaincomp against. Never import chaincomp here.

UniversalRobots/Universal_Robots_ROS2_Description (BSD-3-Clause): config/ur5e/ and ur3e/default_kinematics.yaml
for the numbers; urdf/inc/ur_common.xacro (read_model_data) and urdf/ur_macro.xacro for their
meaning: each entry of the kinematics file is the <origin xyz rpy> of one of the six joints,
each turning about its z, after base_link -> base_link_inertia (rpy 0 0 pi) and before
wrist_3_link -> flange (rpy 0 -pi/2 -pi/2) -> tool0 (rpy pi/2 0 pi/2); URDF's R = Rz(yaw)
Ry(pitch) Rx(roll), metres and radians.
"""

import math

import numpy as np

SEGMENTS = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")
JOINTS = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
          "wrist_3_joint")
LINKS = ("base_link_inertia", "shoulder_link", "upper_arm_link", "forearm_link", "wrist_1_link", "wrist_2_link",
         "wrist_3_link")
# config/ur5e/default_kinematics.yaml (x y z roll pitch yaw per segment)
UR5E = {"shoulder": (0, 0, 0.1625, 0, 0, 0), "upper_arm": (0, 0, 0, 1.570796327, 0, 0),
        "forearm": (-0.425, 0, 0, 0, 0, 0), "wrist_1": (-0.3922, 0, 0.1333, 0, 0, 0),
        "wrist_2": (0, -0.0997, -2.044881182297852e-11, 1.570796327, 0, 0),
        "wrist_3": (0, 0.09959999999999999, -2.042830148012698e-11, 1.570796326589793, 3.141592653589793,
                    3.141592653589793)}
# config/ur3e/default_kinematics.yaml
UR3E = {"shoulder": (0, 0, 0.15185, 0, 0, 0), "upper_arm": (0, 0, 0, 1.570796327, 0, 0),
        "forearm": (-0.24355, 0, 0, 0, 0, 0), "wrist_1": (-0.2132, 0, 0.13105, 0, 0, 0),
        "wrist_2": (0, -0.08535, -1.750557762378351e-11, 1.570796327, 0, 0),
        "wrist_3": (0, 0.0921, -1.8890025766262e-11, 1.570796326589793, 3.141592653589793, 3.141592653589793)}
TOOL = (30.0, -20.0, 120.0)   # mm in tool0


def rot(rpy):
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


def frame(xyz, rpy):
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = rot(rpy), xyz
    return m


def fk(kin, q):
    """tool0 in base_link (metres) at joint angles q (6, rad), from the file's definition."""
    m = frame((0, 0, 0), (0, 0, math.pi))
    for seg, angle in zip(SEGMENTS, q):
        x, y, z, roll, pitch, yaw = kin[seg]
        m = m @ frame((x, y, z), (roll, pitch, yaw)) @ frame((0, 0, 0), (0, 0, angle))
    return m @ frame((0, 0, 0), (0, -math.pi / 2, -math.pi / 2)) @ frame((0, 0, 0), (math.pi / 2, 0, math.pi / 2))


def urdf_text(kin):
    """The URDF ur_macro.xacro expands to for these kinematics (the kinematic part)."""
    links = ["base_link", *LINKS, "flange", "tool0"]
    out = ['<?xml version="1.0"?>', '<robot name="ur5e">'] + [f'  <link name="{n}"/>' for n in links]
    out.append('  <joint name="base_link-base_link_inertia" type="fixed"><parent link="base_link"/>'
               '<child link="base_link_inertia"/><origin xyz="0 0 0" rpy="0 0 3.141592653589793"/></joint>')
    for i, (seg, joint) in enumerate(zip(SEGMENTS, JOINTS)):
        x, y, z, roll, pitch, yaw = kin[seg]
        out.append(f'  <joint name="{joint}" type="revolute"><parent link="{LINKS[i]}"/><child link="{LINKS[i + 1]}"/>'
                   f'<origin xyz="{x!r} {y!r} {z!r}" rpy="{roll!r} {pitch!r} {yaw!r}"/><axis xyz="0 0 1"/>'
                   '<limit lower="-6.283185307179586" upper="6.283185307179586" effort="150" velocity="3.14"/></joint>')
    out.append('  <joint name="wrist_3-flange" type="fixed"><parent link="wrist_3_link"/><child link="flange"/>'
               '<origin xyz="0 0 0" rpy="0 -1.5707963267948966 -1.5707963267948966"/></joint>')
    out.append('  <joint name="flange-tool0" type="fixed"><parent link="flange"/><child link="tool0"/>'
               '<origin xyz="0 0 0" rpy="1.5707963267948966 0 1.5707963267948966"/></joint>')
    return "\n".join(out + ["</robot>"]) + "\n"


def calibration_text(kin, digest="calib_12788084448423163542"):
    lines = ["kinematics:"]
    for seg in SEGMENTS:
        lines.append(f"  {seg}:")
        lines += [f"    {k}: {v!r}" for k, v in zip(("x", "y", "z", "roll", "pitch", "yaw"), kin[seg])]
    return "\n".join(lines + [f"  hash: {digest}"]) + "\n"
