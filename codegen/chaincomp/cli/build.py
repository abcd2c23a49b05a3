"""``chaincomp build``: a machine's model as a shared library for chaincompd and replay."""

from __future__ import annotations

import os
import sys

from ..emit.build import RT_MODULE, build, build_linuxcnc, copy_to, install_rt
from ..errors import ChaincompError
from .common import _same_file, refuse_empty


def add_parser(sub) -> None:
    p = sub.add_parser("build", help="compile a machine's model into a shared library (models built at run time)",
                       description="Generate the machine's C++ and compile it with the C++ build's compiler and "
                                   "flags into a shared library that chaincompd and chaincomp replay load at "
                                   "start-up (they build it themselves when needed; this verb does it ahead). "
                                   "The library is cached by the file's content hash, the ABI version, the "
                                   "compiler and the flags under $XDG_CACHE_HOME/chaincomp (default "
                                   "~/.cache/chaincomp); a cached one is reused. Prints the library's path.")
    p.add_argument("machine", metavar="MACHINE.yaml", help="machine description (any folder)")
    p.add_argument("-o", "--output", metavar="DIR",
                   help="also copy the library to DIR/NAME.so (for --model LIB.so on a computer without a "
                        "compiler)")
    p.add_argument("--linuxcnc", action="store_true",
                   help=f"build the realtime LinuxCNC HAL component {RT_MODULE}.so instead: the machine's "
                        "compensation in the servo thread, its params baked in (needs linuxcnc-uspace-dev)")
    p.add_argument("--params", metavar="P.yaml",
                   help="with --linuxcnc: the error values the component compensates (default: every error "
                        "zero); constant values only, no tables")
    p.add_argument("--name", default=RT_MODULE, metavar="MODULE",
                   help=f"with --linuxcnc: the module's name for loadrt (default {RT_MODULE}; its pins are "
                        "named MODULE with - for _, e.g. chaincomp-rt.joint.0.correction): one per machine "
                        "when a controller holds several")
    p.add_argument("--install", action="store_true",
                   help=f"with --linuxcnc: also copy {RT_MODULE}.so into LinuxCNC's module folder "
                        "(/usr/lib/linuxcnc/modules; root), where loadrt finds it")
    p.set_defaults(run=run)


def run(args) -> int:
    refuse_empty(("-o", args.output), hint="expected a folder")
    refuse_empty(("--params", args.params), hint="leave the option out for every error zero")
    if args.output:  # before the build: a bad folder should not cost a compile
        parent = os.path.dirname(os.path.abspath(args.output))
        if os.path.exists(args.output) and not os.path.isdir(args.output):
            raise ChaincompError(f"-o {args.output}: is a file, expected a folder")
        if not os.path.isdir(parent):
            raise ChaincompError(f"-o {args.output}: folder {parent} does not exist")
        if not os.access(args.output if os.path.isdir(args.output) else parent, os.W_OK):
            raise ChaincompError(f"-o {args.output}: not writable")
    for given, option in ((args.params, "--params"), (args.install, "--install"), (args.name != RT_MODULE, "--name")):
        if given and not args.linuxcnc:
            raise ChaincompError(f"{option} goes with --linuxcnc")
    if args.linuxcnc:
        path, cached = build_linuxcnc(args.machine, args.params, args.name)
    else:
        path, cached = build(args.machine)
    if cached:
        print(f"chaincomp build: {args.machine}: cached", file=sys.stderr)
    if args.output:   # DIR/NAME.so may be the machine file itself (the name is known only now)
        target = os.path.join(args.output, os.path.basename(path))
        if _same_file(target, args.machine):
            raise ChaincompError(f"-o {args.output}: {target} is also an input ({args.machine}); "
                                 "refusing to overwrite it")
    print(copy_to(path, args.output) if args.output else path)
    if args.install:
        print(install_rt(path))
    return 0
