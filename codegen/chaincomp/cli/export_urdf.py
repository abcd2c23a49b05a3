"""``chaincomp export-urdf``: the calibrated URDF (chaincomp.model.urdf_out) of a machine file
imported from a URDF, checked against the machine's own model before it is written."""

from __future__ import annotations

import json
import os
import tempfile

import numpy as np

from ..errors import ChaincompError
from ..model.machine import load_machine
from ..model.params import load_params
from ..model import ur_calibration
from ..model.urdf import BLOCK_SYMBOLS, kinematic_path, machine_text
from ..model.urdf_out import calibrated_urdf
from ..output import write_file
from ..symbolic.numeric import ExactModel
from .common import add_format_argument, add_machine_argument, check_output

POSES = 200          # random poses within the limits at which the two models are compared
TOLERANCE_MM = 1e-9  # the calibrated URDF's tool point against the machine's, at every pose
TOLERANCE_RAD = 1e-12


def add_parser(sub) -> None:
    p = sub.add_parser("export-urdf", help="write the calibrated URDF: identified joint errors folded into the origins",
                       description="Fold the errors of a params file (identify's, or any) into the <origin> of each "
                                   "moving joint of ROBOT.urdf between --base and --tip, the path MACHINE.yaml was "
                                   "imported from (import-urdf --errors origins|joint-offsets|all): origin . "
                                   "T(dx,dy,dz) Rx(ex) Ry(ey) Rz(ez) . the joint's motion by its zero offset. The "
                                   "rest of the file is kept as written. Before writing, the calibrated URDF is "
                                   f"imported again and its tool pose compared with the machine's at {POSES} random "
                                   f"poses within the limits: refused beyond {TOLERANCE_MM:g} mm or "
                                   f"{TOLERANCE_RAD:g} rad.")
    add_machine_argument(p)
    p.add_argument("urdf", metavar="ROBOT.urdf", help="the URDF the machine file was imported from")
    p.add_argument("--base", required=True, metavar="LINK", help="as given to import-urdf")
    p.add_argument("--tip", required=True, metavar="LINK", help="as given to import-urdf")
    p.add_argument("--params", required=True, metavar="P.yaml", help="the errors to fold in (constants only)")
    p.add_argument("--as", dest="form", choices=("urdf", "ur-calibration"), default="urdf",
                   help="what to write: the calibrated URDF (default), or UR's kinematics calibration file "
                        "(kinematics: shoulder .. wrist_3: x y z roll pitch yaw, the origins of the six joints as "
                        "ur_description's xacro reads them; the path must be that form: six joints about z)")
    p.add_argument("-o", "--output", required=True, metavar="OUT.urdf|OUT.yaml", help="calibrated file to write")
    add_format_argument(p, what="summary format on stdout")
    p.set_defaults(run=run)


def _tool(machine):
    vectors = (machine.point, machine.direction, machine.reference)
    return [None if v is None else [float(e.value({})) for e in v] for v in vectors]


def same_pose(machine, values: dict, data: bytes, base: str, tip: str, what: str) -> tuple[float, float]:
    """The largest differences (mm, rad) between the tool pose of the URDF ``data`` imported
    again and the machine's with ``values``, at POSES random poses within the limits; refused
    beyond TOLERANCE_MM or TOLERANCE_RAD (or if the path has other axes)."""
    point, direction, reference = _tool(machine)
    with tempfile.TemporaryDirectory() as tmp:
        urdf = os.path.join(tmp, "calibrated.urdf")
        with open(urdf, "wb") as f:
            f.write(data)
        text = machine_text(urdf, base, tip, "none", point, direction or (0.0, 0.0, 1.0), machine.name, "",
                            reference)
        path = os.path.join(tmp, "calibrated.yaml")
        with open(path, "w", encoding="utf-8") as f:
            f.write(text)
        again = load_machine(path)
    if [a.name for a in again.axes] != [a.name for a in machine.axes]:
        raise ChaincompError(f"the URDF's path {base} -> {tip} has the axes {', '.join(a.name for a in again.axes)}, "
                             f"the machine file {', '.join(a.name for a in machine.axes)}: not the path it was "
                             "imported from", machine.file)
    rng = np.random.default_rng(1)
    axes = {a.name: rng.uniform(a.to_internal(a.limits[0]), a.to_internal(a.limits[1]), POSES) for a in machine.axes}
    want = ExactModel(machine).frame({**values, **axes})
    got = ExactModel(again).frame(dict(axes))
    point_off = float(np.max(np.linalg.norm(np.array(got[0]) - np.array(want[0]), axis=0)))
    turn_off = max((float(np.max(np.linalg.norm(np.array(g) - np.array(w), axis=0)))
                    for g, w in zip(got[1:], want[1:]) if g is not None), default=0.0)
    if not (point_off <= TOLERANCE_MM and turn_off <= TOLERANCE_RAD):
        raise ChaincompError(f"{what}'s tool pose is {point_off:.3g} mm and {turn_off:.3g} rad off the machine's "
                             f"with these errors at {POSES} poses (at most {TOLERANCE_MM:g} mm, {TOLERANCE_RAD:g} "
                             "rad): is MACHINE.yaml imported from this URDF, --base and --tip?", machine.file)
    return point_off, turn_off


def run(args) -> int:
    check_output(args.output, args.machine, args.urdf, args.params)
    machine = load_machine(args.machine)
    values = load_params(args.params, machine)
    varying = sorted(k for k, v in values.items() if not isinstance(v, (int, float)))
    if varying:
        raise ChaincompError(f"{', '.join(varying)}: a table or polynomial cannot go into a URDF origin "
                             "(constants only)", args.params)
    # the tool and base blocks (import-urdf --errors ...,tool,base) have no joint origin to go into: the
    # registration is the instrument's frame, the tool mount chaincomp's tool (left out, and said so)
    blocks = [n for n in BLOCK_SYMBOLS if values.get(n)]
    values = {k: (0.0 if k in blocks else v) for k, v in values.items()}
    data = calibrated_urdf(args.urdf, args.base, args.tip, values)
    point_off, turn_off = same_pose(machine, values, data, args.base, args.tip, "the calibrated URDF")
    if args.form == "ur-calibration":   # the same origins, in UR's kinematics file (model/ur_calibration.py)
        _, joints, _ = kinematic_path(args.urdf, args.base, args.tip)
        data = ur_calibration.text(ur_calibration.ur_joints(joints, "--as ur-calibration"), values, args.params)
    write_file(args.output, data)
    summary = {"output": args.output, "poses": POSES, "max_point_mm": point_off, "max_direction_rad": turn_off,
               "left_out": blocks}
    if args.format == "json":
        print(json.dumps(summary))
    else:
        print(f"wrote {args.output}: at {POSES} poses its tool pose is the machine's within {point_off:.2g} mm "
              f"and {turn_off:.2g} rad"
              + (f" (left out, no joint origin holds them: {', '.join(blocks)})" if blocks else ""))
    return 0
