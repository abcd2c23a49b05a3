"""``chaincomp generate``: allocation-free C++ for one or more machines."""

from __future__ import annotations

import os
import sys
import time

from ..emit.cpp import generate, registry, solver_shape, solvers
from ..errors import ChaincompError
from ..output import write_files
from .common import add_order_argument, check_output, load


def add_parser(sub) -> None:
    p = sub.add_parser("generate", help="emit allocation-free C++ error and compensation functions",
                       description="Write NAME.hpp and NAME.cpp for each machine into DIR: a parameter "
                                   "struct, pose_exact, pose_nominal, pose_jacobian, error_order1..k and "
                                   "compensate, in namespace chaincomp::models::NAME. Output is "
                                   "byte-identical for the same input and sympy version.")
    p.add_argument("machines", nargs="+", metavar="MACHINE.yaml", help="machine descriptions")
    add_order_argument(p, 2, "highest error_order<k> function")
    p.add_argument("-o", "--output", required=True, metavar="DIR", help="output folder (created)")
    p.add_argument("--registry", action="store_true",
                   help="also write registry.cpp mapping each machine name to its functions, and "
                        "solvers.cpp: the compensation solver of each machine shape, once (for models "
                        "compiled with -DCHAINCOMP_PREBUILT_CORE)")
    p.add_argument("--registry-only", action="store_true",
                   help="write registry.cpp and solvers.cpp only (the build generates each machine "
                        "separately)")
    p.set_defaults(run=run)


def run(args) -> int:
    order = args.order
    if os.path.exists(args.output) and not os.path.isdir(args.output):
        raise ChaincompError(f"-o {args.output}: exists and is not a folder")
    there = os.path.abspath(args.output)   # the folder, or the nearest of its parents that exists
    while not os.path.lexists(there):
        there = os.path.dirname(there)
    if not os.path.isdir(there):
        raise ChaincompError(f"-o {args.output}: cannot create output folder: {there} is a file")
    if not os.access(there, os.W_OK):   # before the work, which can take minutes
        raise ChaincompError(f"-o {args.output}: not writable")
    machines = [load(path) for path in args.machines]
    names = [m.name for m in machines]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise ChaincompError(f"two machine files share the name {sorted(dup)[0]!r}")
    written = [] if args.registry_only else [f"{n}.{ext}" for n in names for ext in ("hpp", "cpp")]
    written += ["registry.cpp", "solvers.cpp"] if args.registry or args.registry_only else []
    for fname in written:   # before anything is written: no machine file is overwritten
        path = os.path.join(args.output, fname)
        if os.path.exists(path):
            check_output(path, *args.machines)
    texts = {}
    for m in ([] if args.registry_only else machines):
        start = time.monotonic()
        files = generate(m, order)
        texts.update(files)
        print(f"generate: {m.name}: {', '.join(files)} ({time.monotonic() - start:.1f} s)", file=sys.stderr)
    if args.registry or args.registry_only:
        texts["registry.cpp"] = registry(names)
        texts["solvers.cpp"] = solvers(solver_shape(m) for m in machines)
    # all or nothing: a full disk leaves no short header, nor a header without its source
    write_files({os.path.join(args.output, f): text for f, text in texts.items()}, folder=args.output)
    return 0
