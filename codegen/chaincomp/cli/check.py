"""``chaincomp check``: compare hand-derived formulas with the chain; exit 1 when any differ."""

from __future__ import annotations

from ..analysis.check import Result, check, load_formulas
from ..escape import one_line
from .common import add_format_argument, add_machine_argument, add_order_argument, load, to_json


def add_parser(sub) -> None:
    p = sub.add_parser("check", help="compare hand-derived formulas with the ones the chain gives",
                       description="Compare the formulas of FORMULAS.yaml (nominal x/y/z, errors dx/dy/dz, "
                                   "gain entries, a gain matrix or a whole HTM, in plain math text) with "
                                   "those derived from the machine's chain, coefficient by coefficient of "
                                   "the error symbols. Exit 0 when all are equal, 1 when some differ, "
                                   "2 on bad input.")
    add_machine_argument(p)
    p.add_argument("formulas", metavar="FORMULAS.yaml", help="hand-derived formulas (configs/checks/*.yaml)")
    add_order_argument(p, 1, "highest total degree in the errors compared")
    add_format_argument(p)
    p.set_defaults(run=run)


def _defined(r: Result, file_where) -> list:
    return [s for s in file_where + r.formula.where if s.new]


def as_json(machine, ff, order: int, results: list[Result]) -> dict:
    out = {"file": ff.path, "machine": machine.name, "order": order, "chain": ff.chain,
           "equal": all(r.equal for r in results), "formulas": []}
    for r in results:
        out["formulas"].append({
            "name": r.formula.name, "of": r.formula.of, "line": r.formula.line, "equal": r.equal,
            "findings": [{"entry": f.entry, "monomial": str(f.monomial), "kind": f.kind, "whole": f.whole,
                          "printed": str(f.printed), "derived": str(f.derived), "message": f.message()}
                         for f in r.findings],
            "not_compared": [str(t) for t in r.ignored],
            "defined": [{"name": str(s.symbol), "as": str(s.value), "line": s.line}
                        for s in _defined(r, ff.where)],
        })
    return out


def as_text(machine, ff, order: int, results: list[Result]) -> str:
    lines = [f"{one_line(ff.path)} against {machine.name} ({one_line(machine.file)}), order {order}, chain {ff.chain}"]
    for r in results:
        lines.append(f"  {r.formula.name} (line {r.formula.line}): {'equal' if r.equal else 'DIFFERENT'}")
        for f in r.findings:
            lines.append("    - " + (f"{f.entry}: " if f.entry else "") + f.message())
        for s in _defined(r, ff.where):
            lines.append(f"    note: {s.symbol} is not a symbol of {machine.name}; the file defines it as "
                         f"{s.value} (line {s.line})")
        if r.ignored:
            terms = ", ".join(t if t.startswith("-") else "+" + t for t in map(str, r.ignored))
            lines.append(f"    not compared (degree above {order}): {terms}")
    n_diff = sum(not r.equal for r in results)
    lines.append(f"{len(results)} formulas: {len(results) - n_diff} equal, {n_diff} different")
    return "\n".join(lines)


def run(args) -> int:
    machine = load(args.machine)
    order = args.order
    ff = load_formulas(args.formulas, machine)
    results = check(machine, ff, order, progress=True)
    print(to_json(as_json(machine, ff, order, results)) if args.format == "json"
          else as_text(machine, ff, order, results))
    return 0 if all(r.equal for r in results) else 1
