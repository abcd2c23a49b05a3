"""A machine's derived model as a document (``chaincomp report``), Markdown or LaTeX.

Laid out like Freeman & Ford (2003): the symbol table (their Table 1), the chain as an
equation, the nominal pose and the error formulas (their Table 2), and the error gain
matrix. Formulas are collected by error monomial and, inside it, by the factor in the axes
(sin/cos of the rotary axes, powers of the linear ones), one line per pair, so they read
like the paper's.
"""

from __future__ import annotations

import sympy as sp

from .. import escape
from ..model.machine import Machine, Rotation
from ..symbolic.derive import COMPONENTS, Derivation, Progress

_SENSE_NOTE = ("Sign: the sign with which the symbol enters a rotation of the chain, rotations "
               "right-handed with the senses the file states applied; blank where it enters no rotation.")


# ----------------------------------------------------------------------------- content

def _sign(machine: Machine, sym: sp.Symbol) -> str:
    signs = set()
    for el in machine.tool_chain + machine.workpiece_chain:
        if isinstance(el, Rotation) and sym in el.angle.free_symbols:
            c = sp.diff(el.angle, sym)
            signs.add("+" if c.is_positive else "−" if c.is_negative else "±")
    return "±" if len(signs) > 1 else signs.pop() if signs else ""


def symbol_rows(machine: Machine) -> list[tuple[str, str, str, str, str]]:
    """(name, size, sign, unit, definition) per symbol, as in the paper's Table 1."""
    rows = []
    for s in machine.symbols:
        note = ""
        if s.role == "axis":
            note = f" (axis, {s.limits[0]:g} to {s.limits[1]:g} {s.unit.name})"
        elif s.nominal is not None:
            note = f" (nominal {s.nominal:g} {s.unit.name})"
        rows.append((s.name, "Small" if s.small else "Large", _sign(machine, s.sym), s.unit.name,
                     s.meaning + note))
    return rows


def chain_factors(machine: Machine) -> list[tuple[str, list[sp.Expr]]]:
    """('Rx', [angle]) or ('T', [x, y, z]) per element of the serial chain, leftmost first."""
    out = []
    for el in machine.chain:
        if isinstance(el, Rotation):
            out.append((f"R{el.axis}", [el.angle]))
        else:
            out.append(("T", list(el.vector)))
    return out


def grouped(expr: sp.Expr, small: list[sp.Symbol], axes: set) -> list[tuple[sp.Expr, sp.Expr, sp.Expr]]:
    """``expr`` as (error monomial, constant part, axis factor) triples whose products sum to it.

    Error monomials by degree, then in the machine's order; axis factors sorted, the one
    free of axes last and split into its terms.
    """
    index = {s: i for i, s in enumerate(small)}
    groups: dict = {}
    for term in sp.Add.make_args(sp.expand(expr)):
        if term == 0:
            continue
        mono, axis_part, rest = [], [], []
        for f in sp.Mul.make_args(term):
            base, exp = f.as_base_exp()
            if base in index:
                mono += [index[base]] * int(exp)
            elif f.free_symbols & axes:
                axis_part.append(f)
            else:
                rest.append(f)
        key = (tuple(sorted(mono)), sp.Mul(*axis_part))
        groups[key] = groups.get(key, 0) + sp.Mul(*rest)

    def order(k):
        mono, factor = k
        return (len(mono), mono, factor == 1, sp.default_sort_key(factor))
    out = []
    for key in sorted(groups, key=order):
        const = groups[key]
        parts = [const] if key[1] != 1 else sp.Add.make_args(const)   # free of axes: term by term
        for c in parts:
            if c != 0:
                out.append((sp.Mul(*[small[i] for i in key[0]]), c, key[1]))
    return out


# ----------------------------------------------------------------------------- rendering

def _lines(groups, show) -> list[str]:
    """'+ a * b * c' lines, the sign taken out of the constant part where it is negative."""
    out = []
    for mono, const, factor in groups:
        sign = "+"
        if all(t.could_extract_minus_sign() for t in sp.Add.make_args(const)):
            sign, const = "-", -const
        parts = [show(p, p.is_Add) for p in (mono, const, factor) if p != 1]
        out.append(f"{sign} " + " * ".join(parts or ["1"]))
    return out or ["0"]


def _one_line(lines: list[str]) -> str:
    text = " ".join(lines)
    return text[2:] if text.startswith("+ ") else "-" + text[2:] if text.startswith("- ") else text


def _text(e: sp.Expr, paren: bool) -> str:
    return f"({e})" if paren else str(e)


def _formulas(d: Derivation) -> list[tuple[str, str, sp.Expr]]:
    """(section, name, expression) of every formula of the report."""
    out = []
    vectors = [("point", "", d.point)] + ([("direction", "k", d.direction)] if d.direction else [])
    for what, k, vec in vectors:
        for i, c in enumerate(COMPONENTS):
            out.append((f"Nominal tool {what}", f"{k}{c}", d.nominal(vec[i])))
    for what, k, vec in vectors:
        for degree in range(1, d.order + 1):
            title = f"Tool {what} error, terms of degree {degree} in the errors"
            for i, c in enumerate(COMPONENTS):
                out.append((title, f"d{k}{c}", d.degree_part(vec[i], degree)))
    return out


def _gain(d: Derivation) -> tuple[list[str], list[tuple[str, list[sp.Expr]]]]:
    gm = d.gain_matrix()
    columns = list(gm)
    rows = [(s.name, [gm[c][j] for c in columns]) for j, s in enumerate(d.machine.errors)]
    return columns, rows


def markdown(d: Derivation, protocol: str | None = None, progress: bool = False) -> str:
    m = d.machine
    prog = Progress(f"report {m.name}", progress)   # high orders: a minute of grouping terms
    small, axes = d.small, {s.sym for s in m.axes}
    out = [f"# {escape.markdown(m.name)}: geometric error model", "", escape.markdown(m.description), "",
           f"Derived by chaincomp from {escape.markdown(m.file)} to order {d.order} in the errors. Every symbol enters "
           "the formulas in internal units (mm, rad).", "", "## Symbols", "",
           "| Variable | Size | Sign | Unit | Definition |", "|---|---|---|---|---|"]
    out += ["| " + " | ".join(map(escape.markdown, row)) + " |" for row in symbol_rows(m)]
    out += ["", _SENSE_NOTE, "", "## Chain", ""]
    if m.workpiece_chain:
        out += ["The tool relative to the workpiece: inv(reference→workpiece) · (reference→tool).", ""]
    factors = " · ".join(f"{k}({', '.join(map(str, args))})" for k, args in chain_factors(m))
    point = ", ".join(map(str, m.tool_point))
    out += ["```", f"tool point = {factors} · ({point})", "```"]
    section = None
    for title, name, expr in _formulas(d):
        prog.step(f"{title.lower()}: {name}")
        if title != section:
            if section is not None:
                out.append("```")
            out += ["", f"## {title}", "", "```"]
            section = title
        lines = _lines(grouped(expr, small, axes), _text)
        out.append(f"{name} = {lines[0]}")
        out += [" " * (len(name) + 3) + line for line in lines[1:]]
    out += ["```", "", "## Error gain matrix (first order)", "",
            "Coefficient of each error in each component of the tool error.", ""]
    columns, rows = _gain(d)
    out += ["| error | " + " | ".join(columns) + " |", "|---" * (len(columns) + 1) + "|"]
    for name, row in rows:
        cells = [f"`{_one_line(_lines(grouped(e, small, axes), _text))}`" if e != 0 else "0" for e in row]
        out.append(f"| {name} | " + " | ".join(cells) + " |")
    prog.done()
    if protocol:
        out += ["", "## Measurement protocol", ""] + escape.markdown_code_block(protocol.rstrip())
    return "\n".join(out) + "\n"


def latex(d: Derivation, protocol: str | None = None, progress: bool = False) -> str:
    m = d.machine
    prog = Progress(f"report {m.name}", progress)   # high orders: a minute of grouping terms
    small, axes = d.small, {s.sym for s in m.axes}
    names = {s.sym: r"\mathit{" + s.name.replace("_", r"\_") + "}" for s in m.symbols}

    def tex(e: sp.Expr, paren: bool = False) -> str:
        t = sp.latex(e, symbol_names=names)
        return rf"\left({t}\right)" if paren else t

    def block(name: str, expr: sp.Expr) -> list[str]:
        lines = _lines(grouped(expr, small, axes), tex)
        body = [rf"{name} &= {lines[0].replace(' * ', ' ')} \\"]
        body += [rf"  &\quad {line.replace(' * ', ' ')} \\" for line in lines[1:]]
        return body

    out = [r"\documentclass{article}", r"\usepackage{amsmath}", r"\usepackage[margin=2cm]{geometry}",
           r"\allowdisplaybreaks", r"\begin{document}",
           rf"\section*{{{escape.latex(m.name)}: geometric error model}}", escape.latex(m.description), "",
           rf"Derived by chaincomp from \texttt{{{escape.latex(m.file)}}} to order {d.order} in the errors. "
           "Every symbol enters the formulas in internal units (mm, rad).",
           r"\subsection*{Symbols}", r"\begin{tabular}{lllll}", r"Variable & Size & Sign & Unit & Definition \\",
           r"\hline"]
    for n, size, sign, unit, meaning in symbol_rows(m):
        out.append(rf"${names[m.symbol(n).sym]}$ & {size} & {escape.latex(sign)} & {escape.latex(unit)} & "
                   rf"{escape.latex(meaning)} \\")
    out += [r"\end{tabular}", "", escape.latex(_SENSE_NOTE), r"\subsection*{Chain}"]
    if m.workpiece_chain:
        out.append(r"The tool relative to the workpiece: inv(reference$\to$workpiece)$\cdot$(reference$\to$tool).")
    factors = [rf"\mathbf{{{k[0]}}}{('_' + k[1]) if len(k) > 1 else ''}\left({', '.join(tex(a) for a in args)}\right)"
               for k, args in chain_factors(m)]
    factors.append(rf"\left({', '.join(tex(v) for v in m.tool_point)}\right)^T")
    rows = [r" \, ".join(factors[i:i + 4]) for i in range(0, len(factors), 4)]
    out += [r"\begin{align*}", r"\text{tool point} &= " + r" \\ &\quad \cdot ".join(rows), r"\end{align*}"]
    section = None
    for title, name, expr in _formulas(d):
        prog.step(f"{title.lower()}: {name}")
        if title != section:
            if section is not None:
                out.append(r"\end{align*}")
            out += [rf"\subsection*{{{title}}}", r"\begin{align*}"]
            section = title
        out += block(name, expr)
    out += [r"\end{align*}", r"\subsection*{Error gain matrix (first order)}",
            "Coefficient of each error in each component of the tool error.", r"\begin{align*}"]
    columns, rows = _gain(d)
    for name, row in rows:
        for c, e in zip(columns, row):
            if e != 0:
                comp = r"\delta " + (f"k_{c[-1]}" if c.startswith("dk") else c[-1])
                out += block(rf"\partial\, {comp} / \partial {names[m.symbol(name).sym]}", e)
    out.append(r"\end{align*}")
    prog.done()
    if protocol:
        out += [r"\subsection*{Measurement protocol}", r"\begin{verbatim}", escape.latex_verbatim(protocol.rstrip()), r"\end{verbatim}"]
    out.append(r"\end{document}")
    return "\n".join(out) + "\n"
