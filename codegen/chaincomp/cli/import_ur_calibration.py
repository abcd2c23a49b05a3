"""``chaincomp import-ur-calibration``: UR's kinematics calibration file as the errors of a
machine imported from the robot's URDF (chaincomp.model.ur_calibration), checked against the
URDF with the calibration's origins before the params file is written."""

from __future__ import annotations

import json

from ..escape import one_line
from ..measure.calibration import _write_loadable
from ..model import ur_calibration
from ..model.machine import load_machine
from ..model.urdf import kinematic_path
from ..model.urdf_out import with_origins
from .common import add_format_argument, add_machine_argument, check_output
from .export_urdf import POSES, TOLERANCE_MM, TOLERANCE_RAD, same_pose


def add_parser(sub) -> None:
    p = sub.add_parser("import-ur-calibration", help="read UR's kinematics calibration file as errors (a params file)",
                       description="Read Universal Robots' kinematics calibration file (kinematics: shoulder, "
                                   "upper_arm, forearm, wrist_1, wrist_2, wrist_3: x y z roll pitch yaw, hash; as "
                                   "ur_calibration writes it and ur_description's xacro reads it into the six "
                                   "joints' origins) and write the errors of MACHINE.yaml, imported from ROBOT.urdf "
                                   "(ur_description's form, expanded) between --base and --tip with --errors "
                                   "origins or all, that make each joint's origin the calibrated one: the block "
                                   "T(dx,dy,dz) Rx(ex) Ry(ey) Rz(ez) = origin^-1 . calibrated origin, exactly. "
                                   "Before writing, the machine with those errors is compared with the URDF "
                                   f"holding the calibration's origins at {POSES} random poses: refused beyond "
                                   f"{TOLERANCE_MM:g} mm or {TOLERANCE_RAD:g} rad.")
    add_machine_argument(p)
    p.add_argument("urdf", metavar="ROBOT.urdf", help="the URDF the machine file was imported from")
    p.add_argument("calibration", metavar="CALIBRATION.yaml", help="UR's kinematics calibration file")
    p.add_argument("--base", required=True, metavar="LINK", help="as given to import-urdf")
    p.add_argument("--tip", required=True, metavar="LINK", help="as given to import-urdf")
    p.add_argument("-o", "--output", required=True, metavar="P.yaml", help="params file to write")
    add_format_argument(p, what="summary format on stdout")
    p.set_defaults(run=run)


def run(args) -> int:
    check_output(args.output, args.machine, args.urdf, args.calibration)
    machine = load_machine(args.machine)
    origins, digest = ur_calibration.read(args.calibration)
    _, path, text = kinematic_path(args.urdf, args.base, args.tip)
    joints = ur_calibration.ur_joints(path, f"{args.urdf}: --base {args.base} --tip {args.tip}")
    values = ur_calibration.errors_from(joints, origins, machine, args.calibration)
    calibrated = with_origins(text, {j.name: m for j, m in zip(joints, origins)})
    point_off, turn_off = same_pose(machine, values, calibrated, args.base, args.tip, "the calibration")
    lines = [f"# Errors of {one_line(machine.name)} from UR's kinematics calibration {one_line(args.calibration)}"
             f" (hash {one_line(digest) or 'none'}): each joint's origin block = URDF origin^-1 . calibrated origin.",
             f"machine: {machine.name}", "values:"]
    for s in machine.errors:
        lines.append(f'  {s.name}: "{s.from_internal(values[s.name])!r} {s.unit.name}"')
    _write_loadable(args.output, "\n".join(lines) + "\n", machine)
    summary = {"output": args.output, "hash": digest, "poses": POSES, "max_point_mm": point_off,
               "max_direction_rad": turn_off}
    if args.format == "json":
        print(json.dumps(summary))
    else:
        print(f"wrote {args.output}: at {POSES} poses the machine with these errors is the calibrated URDF within "
              f"{point_off:.2g} mm and {turn_off:.2g} rad")
    return 0

