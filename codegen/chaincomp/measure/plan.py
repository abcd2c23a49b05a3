"""What ``chaincomp protocol MACHINE`` prints with its defaults, for any machine (the report's
--protocol section): one place that chooses among the three kinds of protocol."""

from __future__ import annotations

from ..model.machine import Machine
from .pose_design import DEFAULT_POSES, design_poses, design_text, is_arm
from .protocol import build_protocol, to_text
from .protocol_linear import build_linear_protocol, linear_only
from .protocol_linear import to_text as linear_text


def plan_text(machine: Machine, seed: int, assume_zero=()) -> str:
    """The laser runs, diagonals and tracker points of a machine with linear axes only, the pose
    design of an arm (random pool from ``seed``), else the search over the angle grid."""
    if is_arm(machine):
        return design_text(design_poses(machine, DEFAULT_POSES, seed, assume_zero=assume_zero), None)
    if linear_only(machine):
        return linear_text(build_linear_protocol(machine, assume_zero=assume_zero))
    return to_text(build_protocol(machine, assume_zero=assume_zero))
