"""``chaincomp report``: the document's formulas, read back from the Markdown, agree with the
exact model (the chain multiplied numerically; first-order parts by the complex step)."""

import random
import re

import numpy as np
import pytest
import sympy as sp
from sympy.parsing.sympy_parser import parse_expr

from chaincomp import load_machine
from chaincomp.symbolic.numeric import ExactModel

from helpers import BUNDLED, machine_path, run_cli

H = 1e-30


def _report(name, *args):
    return run_cli("report", machine_path(name), *args).stdout


def _blocks(md: str) -> dict:
    """{name: expression text} from the ``name = + a * b`` blocks of the Markdown."""
    out, current = {}, None
    for line in md.splitlines():
        m = re.match(r"^(d?k?[xyz]) = (.*)$", line)
        if m:
            current = m.group(1)
            out.setdefault(current, []).append(m.group(2))
        elif current and line.startswith(" ") and line.strip()[:1] in "+-":
            out[current].append(line.strip())
        else:
            current = None
    return {k: " ".join(v) for k, v in out.items()}


def _gain_cells(md: str, machine) -> dict:
    rows = [line for line in md.splitlines() if line.startswith("| ")]
    header = [c.strip() for c in next(r for r in rows if r.startswith("| error |")).strip("|").split("|")]
    out = {}
    for line in rows:
        cells = [c.strip() for c in line.strip("|").split("|")]
        if cells[0] in {s.name for s in machine.errors}:
            for col, cell in zip(header[1:], cells[1:]):
                out[(col, cells[0])] = cell.strip("`")
    return out


@pytest.mark.slow
@pytest.mark.parametrize("name", BUNDLED)
def test_markdown_formulas_equal_the_exact_model(name):
    machine = load_machine(machine_path(name))
    md = _report(name)
    table = {s.name: s.sym for s in machine.symbols}
    exprs = {k: parse_expr(v, local_dict=table) for k, v in _blocks(md).items()}
    comps = ["x", "y", "z"] + (["kx", "ky", "kz"] if machine.tool_direction else [])
    assert set(exprs) == set(comps) | {"d" + c for c in comps}
    gains = {k: parse_expr(v, local_dict=table) for k, v in _gain_cells(md, machine).items()}
    turns = ["wx", "wy", "wz"] if machine.tool_reference else []     # a tool frame's rotation vector
    assert len(gains) == len(machine.errors) * (len(comps) + len(turns))
    exact = ExactModel(machine)
    rng = random.Random(3)
    for _ in range(3):
        values = {s.name: rng.uniform(0.3, 1.4) for s in machine.symbols}
        errs = {s.name: rng.uniform(-1, 1) for s in machine.errors}
        zero = dict(values, **{n: 0.0 for n in errs})
        p0, d0 = exact.pose(zero)
        p1, d1 = exact.pose(dict(values, **{n: 1j * H * e for n, e in errs.items()}))
        nominal = list(p0) + (list(d0) if d0 else [])
        first = [np.imag(v) / H for v in list(p1) + (list(d1) if d1 else [])]
        at = dict(values, **errs)
        for i, c in enumerate(comps):
            f = lambda e: float(e.evalf(subs={table[n]: v for n, v in at.items()}))  # noqa: E731
            assert f(exprs[c]) == pytest.approx(float(np.real(nominal[i])), abs=1e-9)
            assert f(exprs["d" + c]) == pytest.approx(first[i], abs=1e-9)
        # gain matrix: derivative along one error at a time
        for j, e in enumerate(machine.errors):
            p1, d1 = exact.pose(dict(zero, **{e.name: 1j * H}))
            col = [np.imag(v) / H for v in list(p1) + (list(d1) if d1 else [])]
            for i, c in enumerate(comps):
                g = gains[("d" + c, e.name)]
                got = float(sp.sympify(g).evalf(subs={table[n]: v for n, v in values.items()})) if g != "0" else 0.0
                assert got == pytest.approx(col[i], abs=1e-9), (c, e.name)
            if turns:   # the frame turns by w: each axis v moves by w x v, so w = (x*dx + y*dy + z*dz)/2
                _, z0, x0 = (np.real(np.array(v, complex)) for v in exact.frame(zero))
                _, z1, x1 = exact.frame(dict(zero, **{e.name: 1j * H}))
                dz, dx = np.imag(np.array(z1, complex)) / H, np.imag(np.array(x1, complex)) / H
                y0, dy = np.cross(z0, x0), np.cross(dz, x0) + np.cross(z0, dx)
                w = (np.cross(x0, dx) + np.cross(y0, dy) + np.cross(z0, dz)) / 2
                for i, c in enumerate(turns):
                    g = gains[(c, e.name)]
                    got = float(sp.sympify(g).evalf(subs={table[n]: v for n, v in values.items()})) if g != "0" else 0.0
                    assert got == pytest.approx(w[i], abs=1e-9), (c, e.name)


@pytest.mark.slow
def test_markdown_reads_like_the_paper():
    md = _report("angle_head")
    # Table 1: name, size, sign, unit, meaning
    assert "| Variable | Size | Sign | Unit | Definition |" in md
    assert "| ThetaAs | Small | − | arcsec | Angle between A and the spindle S (sign -ve) |" in md
    assert "| G | Large |  | mm | Spindle length (nominal 20 mm) |" in md
    # the chain as an equation, leftmost first
    assert "tool point = Rx(ThetaCv) · Ry(ThetaCh) · Rz(Cp) · T(0, -e, -e/tan(Yp))" in md
    # collected by error and by axis factor, one pair per line
    assert "dz = + ThetaAs * G*sin(Yp) * sin(Ap)\n" in md
    assert "     - Oas * sin(Yp)*cos(Yp) * cos(Ap)\n     + Oas * sin(Yp)*cos(Yp)\n" in md
    assert "| Ocx | `cos(Cp)` | `sin(Cp)` | 0 | 0 | 0 | 0 |" in md


@pytest.mark.slow
def test_order_two_and_loops():
    md = _report("mori_seiki_nv1500", "--order", "2")
    assert "## Tool point error, terms of degree 2 in the errors" in md
    assert "inv(reference→workpiece) · (reference→tool)" in md


@pytest.mark.slow
def test_latex_document(tmp_path):
    out = tmp_path / "angle_head.tex"
    proc = run_cli("report", machine_path("angle_head"), "-o", str(out))
    assert str(out) in proc.stderr and proc.stdout == ""
    tex = out.read_text()
    assert tex.startswith(r"\documentclass{article}") and tex.rstrip().endswith(r"\end{document}")
    for env in ("document", "align*", "tabular"):
        assert tex.count(rf"\begin{{{env}}}") == tex.count(rf"\end{{{env}}}") > 0
    body = tex.replace(r"\{", "").replace(r"\}", "")
    assert body.count("{") == body.count("}")
    assert r"$\mathit{ThetaAs}$ & Small & $-$ & arcsec &" in tex
    assert _report("angle_head", "--format", "latex") == tex


@pytest.mark.slow
def test_unwritable_output_exits_2(tmp_path):
    target = tmp_path / "missing" / "r.md"
    proc = run_cli("report", machine_path("angle_head"), "-o", str(target), check=False)
    assert proc.returncode == 2
    assert proc.stderr.startswith(f"chaincomp report: error: -o {target}: folder {target.parent} does not exist")


@pytest.mark.slow
def test_report_appends_the_protocol(tmp_path):
    from helpers import machine_path, run_cli
    out = tmp_path / "r.md"
    run_cli("report", machine_path("angle_head"), "--protocol", "--assume-zero", "DY", "-o", str(out))
    proto = run_cli("protocol", machine_path("angle_head"), "--assume-zero", "DY").stdout
    text = out.read_text()
    assert "## Measurement protocol" in text
    tests = [line for line in proto.splitlines() if line.startswith("Test ")]
    assert tests and all(line in text for line in tests)
    bad = run_cli("report", machine_path("angle_head"), "--assume-zero", "DY", check=False)
    assert bad.returncode == 2 and "--assume-zero goes with --protocol" in bad.stderr
