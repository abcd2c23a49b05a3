"""``chaincomp import-urdf``: a machine file from the kinematic path of a URDF (chaincomp.urdf)."""

from __future__ import annotations

import json
import math
import sys

from .. import __version__
from ..analysis.lint import lint
from ..errors import ChaincompError
from ..model.machine import load_machine
from ..model.urdf import ERROR_BLOCKS, ERROR_MODES, machine_text
from ..output import write_file
from .common import add_format_argument, check_output, number_list


def add_parser(sub) -> None:
    p = sub.add_parser("import-urdf", help="write a machine file from a URDF's joints between two links",
                       description="Read ROBOT.urdf (with yourdfpy; meshes are not loaded), walk the joints from "
                                   "--base down to --tip and write them as a machine file: each joint's origin "
                                   "(xyz in mm, rpy as rotations), its motion (revolute and continuous in deg, "
                                   "prismatic in mm, limits converted) and, with --errors, zero offsets and 6-DOF "
                                   "origin errors. Floating, planar and mimic joints are refused. The file is "
                                   "loaded back and linted before it is written.")
    p.add_argument("urdf", metavar="ROBOT.urdf", help="the URDF file (expand a xacro first)")
    p.add_argument("--base", required=True, metavar="LINK", help="link the chain starts from (the machine's reference)")
    p.add_argument("--tip", required=True, metavar="LINK", help="link the tool is fixed to (below --base in the tree)")
    p.add_argument("--errors", default="none", metavar="|".join(ERROR_MODES) + "[,tool][,base]",
                   help="error symbols to declare: joint-offsets (one zero offset per moving joint, arcsec or "
                        "um), origins (a 6-DOF block at each moving joint's origin, um and arcsec), all (both); "
                        "default none; and, after a comma, tool (a 6-DOF block tool_dx .. tool_ez after the tip "
                        "link) and base (base_dx .. base_ez before the chain, marked registration: the measuring "
                        "instrument's frame to the base, reported apart by identify): e.g. "
                        f"origins,{','.join(ERROR_BLOCKS)}")
    p.add_argument("--tool-point", default="0,0,0", metavar="X,Y,Z",
                   help="tool point in the tip link's frame, mm (default 0,0,0)")
    p.add_argument("--tool-direction", default="0,0,1", metavar="X,Y,Z",
                   help="tool direction in the tip link's frame (normalised; default 0,0,1)")
    p.add_argument("--tool-reference", metavar="X,Y,Z",
                   help="a six-DOF tool frame: its x axis, in the tip link's frame (the part orthogonal to "
                        "the tool direction is taken); default none (point and direction only)")
    p.add_argument("--name", help="machine name (default: the URDF robot's name, sanitised)")
    p.add_argument("-o", "--output", required=True, metavar="M.yaml", help="machine file to write")
    add_format_argument(p, what="summary format on stdout")
    p.set_defaults(run=run)


def _vector(option: str, text: str) -> list[float]:
    values = number_list(option, text)
    if len(values) != 3:
        raise ChaincompError(f"{option}: expected three numbers X,Y,Z, got {len(values)}")
    if max(abs(v) for v in values) > 1e15:
        raise ChaincompError(f"{option}: values beyond 1e15 mm")
    if any(0 < abs(v) < 1e-27 for v in values):   # the machine file's numbers stop at 1e-30
        raise ChaincompError(f"{option}: a value below 1e-27 that is not 0 (write 0)")
    return values


def _axis(option: str, text: str) -> list[float]:
    """A direction: three numbers, its length at least the machine loader's 1e-12."""
    values = _vector(option, text)
    if math.hypot(*values) < 1e-12:
        raise ChaincompError(f"{option}: must not be zero (its length is below 1e-12)")
    return values


def run(args) -> int:
    point = _vector("--tool-point", args.tool_point)
    direction = _axis("--tool-direction", args.tool_direction)
    reference = None
    if args.tool_reference is not None:
        reference = _axis("--tool-reference", args.tool_reference)
        # the loader's tests (machine.py): the part orthogonal to the direction becomes the x axis
        along = sum(r * d for r, d in zip(reference, direction)) / sum(d * d for d in direction)
        orthogonal = math.hypot(*(r - along * d for r, d in zip(reference, direction)))
        if orthogonal < max(1e-6 * math.hypot(*reference), 1e-12):
            raise ChaincompError(f"--tool-reference {args.tool_reference}: must not be (nearly) parallel "
                                 f"to the tool direction {args.tool_direction} (its part orthogonal to the "
                                 "direction is the frame's x axis)")
    check_output(args.output, args.urdf)
    text = machine_text(args.urdf, args.base, args.tip, args.errors, point, direction, args.name, __version__,
                        reference)
    # Written beside the output and renamed over it only once it loads: a file that does
    # not load is a bug here, never left behind for the user.
    loaded = []

    def check(tmp: str) -> None:
        try:
            loaded.append(load_machine(tmp))
        except ChaincompError as exc:
            raise RuntimeError(f"the machine file written does not load: {exc}") from None
    write_file(args.output, text, check)
    machine = loaded[0]
    findings = lint(machine)
    for f in findings:
        print(f"chaincomp import-urdf: {f.level}: {args.output}:{f}", file=sys.stderr)
    summary = {"output": args.output, "name": machine.name, "axes": [a.name for a in machine.axes],
               "errors": [e.name for e in machine.errors], "warnings": len(findings)}
    if args.format == "json":
        print(json.dumps(summary, indent=2))
    else:
        print(f"{args.output}: {machine.name}: {len(machine.axes)} axes ({', '.join(summary['axes'])}), "
              f"{len(machine.errors)} errors, {len(findings)} lint warnings")
    return 0
