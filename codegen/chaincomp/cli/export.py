"""``chaincomp export``: compensation in a controller's own format, checked on the exact model."""

from __future__ import annotations

import os
import sys

from ..analysis import export as X
from ..analysis import isg_volcomp as ISG
from ..errors import ChaincompError
from ..model.params import parse_value
from ..output import write_files
from .common import (add_controller_arguments, add_deprecated, add_machine_argument, add_values_arguments, assignments,
                     check_finite, check_output, integer, load, names, refuse_empty, require_controller, to_json,
                     values_for)

MAX_GRID = 101
FORMATS = X.FORMATS + (ISG.FORMAT,)
FOLDERS = ("linuxcnc-comp", ISG.FORMAT)    # formats that write a folder of files


def add_parser(sub) -> None:
    p = sub.add_parser("export", help="compensation in a controller's own format, with the residual it leaves",
                       description="Fits a controller's own compensation to the machine's exact model with the "
                                   "errors of --params, replays it with the controller's own rule over a grid of "
                                   "the working volume (--grid points per axis, limits included) and reports the "
                                   "tool-point error before and after, and for each error alone what the format "
                                   "leaves of it (an error the format cannot represent is left out). Formats: "
                                   "linuxcnc-comp (one [JOINT_n]COMP_FILE per joint: -o is a folder), "
                                   "linuxcnc-matrixkins (C_xx..C_zz of LinuxCNC's matrixkins: -o is a HAL file), "
                                   "marlin (G21, M852 I J K), klipper (SET_SKEW), rrf (M556 P0): -o is the G-code; "
                                   "isg-volcomp (the ISO 230-1 errors in an ISG CSV file and its compensation "
                                   "list, for ISG's and Beckhoff TwinCAT CNC's volumetric compensation: -o is a "
                                   "folder). "
                                   "Nothing is written when anything is refused.")
    add_machine_argument(p)
    add_values_arguments(p)
    add_controller_arguments(p, FORMATS)
    p.add_argument("-o", "--output", required=True, metavar="OUT", help="what to write (a folder for "
                   "linuxcnc-comp and isg-volcomp, a file otherwise)")
    p.add_argument("--grid", type=integer(2, MAX_GRID), metavar="N",
                   help=f"check points per axis, limits included (default 9, fewer on a chain of more than five "
                        f"axes: at most {X.DEFAULT_GRID_POINTS} in all; at most {X.MAX_POINTS} when given)")
    p.add_argument("--entries", type=integer(2, X.LINUXCNC_MAX_ENTRIES), default=33, metavar="N",
                   help=f"linuxcnc-comp: entries per joint, equally spaced over its limits (default 33, at most "
                        f"{X.LINUXCNC_MAX_ENTRIES}: LinuxCNC's EMCMOT_COMP_SIZE); isg-volcomp: records of each "
                        f"error that varies, over its axis' limits (and a linear table's own knots)")
    p.add_argument("--workpiece-axes", type=integer(0, 5), default=0, metavar="N",
                   help="isg-volcomp: workpiece_axes of the compensation list (P-VOLC-00008; default 0: the errors "
                        "are ISO 230-1's, the tool's relative to the workpiece)")
    p.add_argument("--iso-axes", metavar="X=A1,Y=A2,...", help="isg-volcomp: the ISO 230-1 letter of each axis "
                   "(default: axes named X, Y, Z, A, B, C, or a rotary axis whose name starts with A, B or C)")
    p.add_argument("--comp-file-type", type=int, choices=(0, 1), default=1,
                   help="linuxcnc-comp: COMP_FILE_TYPE 1 (nominal, forward trim, reverse trim; default) or 0 "
                        "(nominal, position reached forward, reverse)")
    p.add_argument("--joints", metavar="A1,A2,...", help="the machine's axes in the controller's joint order "
                   "(default the machine file's order); matrixkins and the printers take the first three linear "
                   "ones as X, Y, Z")
    p.add_argument("--mean-reversal", action="append", default=[], metavar="AXIS=VALUE",
                   help="linuxcnc-comp: the signed mean reversal B̄ of an axis (ISO 230-2, mean of B_i = x̄_i↑ - "
                        "x̄_i↓, as 'chaincomp iso230-2' prints it to pass; negative for ordinary lost motion, e.g. "
                        "X=-8um; repeatable): the forward trim takes -B̄/2, the reverse +B̄/2 (the model itself has "
                        "no reversal). LinuxCNC ignores [JOINT_n]BACKLASH once a COMP_FILE is loaded: the reversal "
                        "belongs here")
    add_deprecated(p, "--reversal", "--mean-reversal with the value 'chaincomp iso230-2' prints (the signed mean B̄, "
                   "negative for ordinary lost motion, not B = max |B_i|)", "reversal", append=True, default=[],
                   metavar="AXIS=VALUE")
    p.add_argument("--no-breakdown", action="store_true", help="skip the fit of each error alone")
    p.set_defaults(run=run)


def _reversal(machine, mean: list[str], deprecated: list[str]) -> dict[str, float]:
    """The signed mean reversal B̄ per axis, in the axis' unit, from --mean-reversal and its
    deprecated alias --reversal (which once asked for B = max |B_i| >= 0: copied from
    iso230-2, that positive value doubled an ordinary lost motion instead of removing it)."""
    option = "--mean-reversal" if mean or not deprecated else "--reversal"
    out = {}
    for name, raw in assignments(mean + deprecated, option, "AXIS=VALUE, e.g. X=-8um").items():
        if name not in [a.name for a in machine.axes]:
            raise ChaincompError(f"{option} {name}: not an axis of {machine.name} "
                                 f"({', '.join(a.name for a in machine.axes)})")
        axis = machine.symbol(name)
        try:
            out[name] = axis.from_internal(parse_value(axis, raw))
        except ValueError as exc:
            raise ChaincompError(f"{option} {name}={raw}: {exc}") from None
    return out


def _iso_axes(text: str | None) -> dict[str, str] | None:
    if text is None:
        return None
    items = names(text, "--iso-axes")
    if not items:
        raise ChaincompError("--iso-axes: empty (expected LETTER=AXIS,..., e.g. X=X1,Y=Y1,Z=Z1)")
    return assignments(items, "--iso-axes", "LETTER=AXIS, e.g. X=X1,A=Ap")


def _outputs(e: X.Export, out: str, file_type: int, isg: tuple[str, str] | None) -> dict[str, str]:
    """Every file to write, path -> text."""
    if isg:
        return {os.path.join(out, ISG.CSV_FILE): isg[0], os.path.join(out, ISG.LIST_FILE): isg[1]}
    if e.format == "linuxcnc-comp":
        files = _comp_files([t.axis for t in e.tables])
        texts = {os.path.join(out, f): X.linuxcnc_comp_text(t, file_type) for f, t in zip(files, e.tables)}
        texts[os.path.join(out, "compensation.ini")] = X.linuxcnc_ini_text(e, file_type, files)
        return texts
    if e.format == "linuxcnc-matrixkins":
        return {out: X.matrixkins_text(e)}
    return {out: X.skew_text(e) + "\n"}


def _comp_files(axes) -> list[str]:
    return [f"joint{n}_{a.name}.comp" for n, a in enumerate(axes)]


def _check_folder(out: str, files: list[str], inputs, fmt: str) -> None:
    """The folder a format writes, and each file in it (before the work: none is an input, a
    folder, or read-only)."""
    refuse_empty(("-o", out), hint="expected a folder name")
    if os.path.exists(out) and not os.path.isdir(out):
        raise ChaincompError(f"-o {out}: {fmt} writes a folder of files; {out} is a file")
    parent = os.path.dirname(os.path.abspath(out))
    if not os.path.isdir(parent):
        raise ChaincompError(f"-o {out}: folder {parent} does not exist")
    if not os.access(out if os.path.isdir(out) else parent, os.W_OK):
        raise ChaincompError(f"-o {out}: not writable")
    if os.path.isdir(out):
        for f in files:
            check_output(os.path.join(out, f), *inputs)


def run(args) -> int:
    require_controller(args, FORMATS)
    machine = load(args.machine)
    joints = names(args.joints, "--joints") or None
    if args.target == "linuxcnc-comp":
        _check_folder(args.output, _comp_files(X.axes_of(machine, joints)) + ["compensation.ini"],
                      [args.machine, args.params], args.target)
    elif args.target == ISG.FORMAT:
        _check_folder(args.output, [ISG.CSV_FILE, ISG.LIST_FILE], [args.machine, args.params], args.target)
    else:
        check_output(args.output, args.machine, args.params)
    for item in args.sets:
        name = item.partition("=")[0].strip()
        if name in [a.name for a in machine.axes]:
            raise ChaincompError(f"--set {item}: {name} is an axis; export checks every axis over its limits")
    iso_axes = _iso_axes(args.iso_axes)
    if iso_axes is not None and args.target != ISG.FORMAT:
        raise ChaincompError(f"--iso-axes: only {ISG.FORMAT} names its axes by ISO letter, not {args.target}")
    if args.workpiece_axes and args.target != ISG.FORMAT:
        raise ChaincompError(f"--workpiece-axes: only {ISG.FORMAT} has it, not {args.target}")
    reversal = _reversal(machine, args.mean_reversal, args.reversal)
    if reversal and args.target != "linuxcnc-comp":
        raise ChaincompError(f"{'--mean-reversal' if args.mean_reversal else '--reversal'}: only linuxcnc-comp has "
                             f"a reverse trim, not {args.target}")
    values, has_errors = values_for(machine, args.params, args.sets)
    if not has_errors:
        raise ChaincompError("nothing to compensate: give error values (--params P.yaml or --set E=V)")

    def progress(text: str) -> None:
        print(f"export: {text}", file=sys.stderr, flush=True)

    grid = args.grid or X.default_grid(len(machine.axes))
    isg = None
    if args.target == ISG.FORMAT:
        e, *isg = ISG.export(machine, values, joints, grid, args.entries, iso_axes, args.workpiece_axes,
                             shares=not args.no_breakdown, progress=progress)
    else:
        e = X.export(machine, values, args.target, joints, grid, args.entries, reversal,
                     shares=not args.no_breakdown, progress=progress)
    texts = _outputs(e, args.output, args.comp_file_type, isg)
    doc = X.to_json(e)
    check_finite(doc)
    write_files(texts, folder=args.output if args.target in FOLDERS else None)   # all complete, then in place
    for path in texts:
        print(f"export: wrote {path}", file=sys.stderr)
    print(to_json(doc) if args.format == "json" else X.to_text(e))
    return 0
