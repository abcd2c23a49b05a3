"""Hostile and careless input to the math parser and the YAML loaders: nothing runs code,
every bound refuses with its own message (file, line, field; exit 2), work stays bounded.

The injection payloads try to make Python run `touch MARKER`; each test checks that the
marker file was never created, whatever the exit code.
"""

import subprocess
import sys
import time

import pytest
import sympy as sp
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from chaincomp.errors import ChaincompError
from chaincomp.model.expressions import MAX_DEPTH, MAX_LENGTH, ExpressionError, parse
from chaincomp.model.machine import load_machine

from test_machine_file_errors import MACHINE, PARAMS, edit
from helpers import ROOT, line_of



def run(*args, cwd=ROOT, timeout=120):
    return subprocess.run([sys.executable, "-m", "chaincomp.cli.main", *args], capture_output=True,
                          text=True, cwd=cwd, timeout=timeout)


def payloads(marker: str) -> list[str]:
    cmd = f"touch {marker}"
    return [
        f"-Y1 + 0*(lambda: 0).__globals__['__builtins__']['__import__']('os').system('{cmd}')",
        f"__import__('os').system('{cmd}')",
        f"Y1 + eval(\"__import__('os').system('{cmd}')\")",
        "Y1.__class__.__mro__[1].__subclasses__()",
        "[x for x in ().__class__.__base__.__subclasses__()]",
        f"Y1 if __import__('os').system('{cmd}') else Y1",
        f"exec('import os; os.system(\"{cmd}\")')",
        "Y1 + Function('system')(1)",
        "Y1 + Symbol('__import__')",
        f"Integer(__import__('os').system('{cmd}'))",
    ]


SYMS = {n: sp.Symbol(n, real=True) for n in ("X", "Y1", "Z", "L", "EXX")}


def test_parser_refuses_every_payload(tmp_path):
    marker = tmp_path / "MARKER"
    for text in payloads(str(marker)):
        with pytest.raises(ExpressionError):
            parse(text, SYMS)
    assert not marker.exists()


# Every text field of a machine file that becomes math, as (old, new-with-{p}) edits of MACHINE.
MACHINE_FIELDS = [
    ("chain[0].translate[1]", "[X, Y1, 0]", "[X, \"{p}\", 0]"),
    ("chain[1].errors.dx", "{dx: dx1,", "{dx: \"dx1 + {p}\","),
    ("chain[2].translate[2]", "[0, Y2, Z]", "[0, Y2, \"{p}\"]"),
    ("tool.point[0]", "point: [tx, ty, tz]", "point: [\"{p}\", ty, tz]"),
]


@pytest.mark.slow
@pytest.mark.parametrize("field,old,new", MACHINE_FIELDS, ids=[f[0] for f in MACHINE_FIELDS])
def test_payload_in_machine_fields_never_runs(tmp_path, field, old, new):
    marker = tmp_path / "MARKER"
    for i, p in enumerate(payloads(str(marker))[:4]):
        p = p.replace('"', "'")  # inside a YAML double-quoted string
        path = tmp_path / f"m{i}.yaml"
        path.write_text(edit(MACHINE, (old, new.replace("{p}", p))))
        proc = run("eval", str(path))
        assert proc.returncode == 2, proc.stderr
        assert "Traceback" not in proc.stderr
        assert f"{path}:{line_of(path.read_text(), new.split('{p}')[0])}: {field}: " in proc.stderr, proc.stderr
    assert not marker.exists()


@pytest.mark.slow
def test_payload_in_params_set_check_and_tolerances_never_runs(tmp_path):
    marker = tmp_path / "MARKER"
    p = payloads(str(marker))[0].replace('"', "'")
    m = tmp_path / "m.yaml"
    m.write_text(MACHINE)
    params = tmp_path / "p.yaml"
    params.write_text(edit(PARAMS, ("dx1: 3 um", f'dx1: "{p}"')))
    check = tmp_path / "c.yaml"
    check.write_text("machine: me220_xz\nwhere:\n  k: \"%s\"\nformulas:\n  - {name: a, of: dx, formula: \"%s\"}\n"
                     % (p, p))
    tol = tmp_path / "t.yaml"
    tol.write_text(f'tolerances:\n  dx1: {{bound: "{p}", distribution: uniform}}\n')
    procs = [run("eval", str(m), "--params", str(params)),
             run("eval", str(m), "--set", f"dx1={p}"),
             run("check", str(m), str(check)),
             run("budget", str(m), "--tolerances", str(tol), "--grid", "2")]
    for proc in procs:
        assert proc.returncode == 2, proc.stderr
        assert "Traceback" not in proc.stderr
    assert f"{params}:{line_of(params.read_text(), 'dx1:')}: values.dx1: " in procs[0].stderr
    assert f"{check}:3: where.k: " in procs[2].stderr
    assert f"{tol}:2: " in procs[3].stderr
    assert not marker.exists()


BOUNDS = [
    ("X*2**(10**10)", "exponent 10000000000"),
    ("X^65", "larger than 64"),
    ("(X+1)**8**2*X", "degree"),
    ("X" + "*X" * 64, "degree"),
    ("(" * (MAX_DEPTH + 1) + "X" + ")" * (MAX_DEPTH + 1), f"nested more than {MAX_DEPTH} deep"),
    ("-" * (MAX_DEPTH + 1) + "X", f"nested more than {MAX_DEPTH} deep"),
    ("X + " * (MAX_LENGTH // 4) + "X", f"at most {MAX_LENGTH}"),
    ("1" * 41, "more than 40 characters"),
    ("2e16*X", "larger than 1e+15"),
    ("1e-31", "smaller than"),
    ("(10**15)**7", "larger than 1e+100"),
    ("X**pi", "constant rational"),
    ("X**Z", "constant rational"),
    ("1/(X-X)", "division by zero"),
    ("sqrt(-1)", "not real"),
    ("atan2(0, 0)", "not finite"),
    ("3!", "unexpected character '!'"),
    ("0x1F", "unexpected 'x'"),
    ("X.real", "unexpected '.'"),
    ("sin X", "expected '('"),
    ("atan2(X)", "atan2 takes 2 arguments"),
    ("cosh(X)", "unknown function 'cosh'"),
    ("X(2)", "unknown function 'X'"),
    ("sin", "expected '('"),
    ("X +", "ends too early"),
    ("(X", "ends too early"),
    ("X)", "unexpected ')'"),
]


@pytest.mark.parametrize("text,word", BOUNDS, ids=[b[1] + f"-{i}" for i, b in enumerate(BOUNDS)])
def test_parser_bounds(text, word):
    start = time.monotonic()
    with pytest.raises(ExpressionError, match=None) as info:
        parse(text, SYMS)
    assert word in str(info.value), str(info.value)
    assert time.monotonic() - start < 2.0


def test_parser_grammar():
    X, Z = SYMS["X"], SYMS["Z"]
    # the grammar of docs/reference/machine-file.md ("Math text is parsed"), truth written by hand
    assert parse("X^2^3", SYMS) == X ** 8            # right-associative
    assert parse("-X**2", SYMS) == -(X ** 2)         # the power binds tighter than the sign
    assert parse("2**-1", SYMS) == sp.Rational(1, 2)
    assert parse("1.5e-3*X", SYMS) == sp.Rational(3, 2000) * X   # decimals exact
    assert parse(".5 + 2.", SYMS) == sp.Rational(5, 2)
    assert parse("X**(1/2)", SYMS) == sp.sqrt(X)
    assert parse("atan2(X, Z) + pi", SYMS) == sp.atan2(X, Z) + sp.pi
    assert parse("X ^ 2 ** 2", SYMS) == X ** 4       # both spellings, mixed
    assert parse(12, SYMS) == 12 and parse(0.1, SYMS) == sp.Rational(1, 10)
    assert parse("X - Z - X", SYMS) == -Z            # left-associative
    assert parse("X / Z / X", SYMS) == 1 / Z


def test_parser_refuses_non_finite_numbers():
    for value in (float("nan"), float("inf"), 10 ** 400, True, None, [1]):
        with pytest.raises(ExpressionError):
            parse(value, SYMS)


_ALPHABET = st.sampled_from(list("XYZL1EXX()+-*/^., ") + ["**", "sin(", "sqrt(", "atan2(", "pi", "1e9",
                                                          "__", "'", "[", "lambda", ":"])


@pytest.mark.slow
@settings(max_examples=400, deadline=2000, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(_ALPHABET, max_size=40).map("".join))
def test_parser_property_random_tokens(text):
    """Random token soup: a sympy expression over the declared symbols, or ExpressionError."""
    try:
        e = parse(text, SYMS)
    except ExpressionError:
        return
    assert isinstance(e, sp.Expr) and e.free_symbols <= set(SYMS.values())


@settings(max_examples=300, deadline=2000)
@given(st.text(max_size=60))
def test_parser_property_random_text(text):
    try:
        parse(text, SYMS)
    except ExpressionError:
        pass


@settings(max_examples=150, deadline=5000, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.recursive(st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=10),
                    lambda kids: st.lists(kids, max_size=4) | st.dictionaries(st.text(max_size=6), kids,
                                                                              max_size=4), max_leaves=20),
       st.sampled_from(["name", "symbols", "chain", "tool", "loop", "error_block_order"]))
@pytest.mark.slow
def test_machine_loader_property_random_yaml(tmp_path, value, key):
    """A random YAML value in place of a top-level field: ChaincompError or a machine."""
    import yaml
    doc = yaml.safe_load(MACHINE)
    doc[key] = value
    path = tmp_path / "random.yaml"
    path.write_text(yaml.safe_dump(doc, allow_unicode=True))
    try:
        load_machine(str(path))
    except ChaincompError:
        pass


def _cli_refuses(tmp_path, text, word, line=None, field=None):
    path = tmp_path / "m.yaml"
    path.write_text(text)
    proc = run("derive", str(path), timeout=60)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    where = f"{path}:{line}: " if line else f"{path}"
    assert where in proc.stderr, proc.stderr
    if field:
        assert f" {field}: " in proc.stderr, proc.stderr
    assert word in proc.stderr, proc.stderr


@pytest.mark.slow
def test_yaml_alias_bomb_refused(tmp_path):
    bomb = "a: &a [x, x, x, x, x, x, x, x, x, x]\n"
    for i in range(1, 9):
        bomb += f"{chr(97 + i)}: &{chr(97 + i)} [" + ", ".join([f"*{chr(96 + i)}"] * 10) + "]\n"
    text = edit(MACHINE, ("description: ME220 notes' X/Z two-slide example with positioning, yaw and pitch errors",
                          "bomb:\n" + "".join("  " + l + "\n" for l in bomb.splitlines()) + "description: [*i]"))
    start = time.monotonic()
    _cli_refuses(tmp_path, text, "aliases expand the document")
    assert time.monotonic() - start < 30


@pytest.mark.slow
def test_yaml_depth_refused(tmp_path):
    deep = "[" * 5000 + "]" * 5000
    text = edit(MACHINE, ("description: ME220 notes' X/Z two-slide example with positioning, yaw and pitch errors",
                          f"description: {deep}"))
    _cli_refuses(tmp_path, text, "nested more than 64 levels", line=line_of(text, "description:"))


def test_yaml_aliases_used_sensibly_still_load(tmp_path):
    text = edit(MACHINE, ("{name: Y1, role: constant, unit: mm, nominal: 50,",
                          "{name: Y1, role: constant, unit: &u mm, nominal: 50,"),
                ("{name: Y2, role: constant, unit: mm,", "{name: Y2, role: constant, unit: *u,"))
    path = tmp_path / "m.yaml"
    path.write_text(text)
    assert load_machine(str(path)).symbol("Y2").unit.name == "mm"


@pytest.mark.slow
def test_file_size_and_kind_refused(tmp_path):
    big = tmp_path / "big.yaml"
    with open(big, "w") as f:
        f.write(MACHINE)
        f.write("# " + "x" * (17 * 1024 * 1024) + "\n")
    proc = run("derive", str(big))
    assert proc.returncode == 2 and "larger than 16 MiB" in proc.stderr, proc.stderr
    proc = run("derive", str(tmp_path))
    assert proc.returncode == 2 and "not a regular file" in proc.stderr, proc.stderr
    bad = tmp_path / "latin1.yaml"
    bad.write_bytes(MACHINE.replace("description: ME220", "description: Zürich ME220").encode("latin-1"))
    proc = run("derive", str(bad))
    assert proc.returncode == 2 and f"{bad}:3: not UTF-8 text (byte 0xfc)" in proc.stderr, proc.stderr


@pytest.mark.slow
@pytest.mark.parametrize("name", ["me220_xz\n", "int", "NAN", "errno", "namespace", "M_PI", "std"])
def test_names_that_break_the_cpp_refused(tmp_path, name):
    as_yaml = '"me220_xz\\n"' if name.endswith("\n") else name
    text = edit(MACHINE, ("name: me220_xz", f"name: {as_yaml}"))
    _cli_refuses(tmp_path, text, "", line=2, field="name")
    # the same name as a symbol
    if not name.endswith("\n"):
        text = edit(MACHINE, ("{name: ty,", f"{{name: {name},"), ("[tx, ty, tz]", f"[tx, {name}, tz]"))
        _cli_refuses(tmp_path, text, "reserved", field="symbols[5].name")


@pytest.mark.slow
def test_symbol_name_with_trailing_newline_refused(tmp_path):
    text = edit(MACHINE, ("{name: ty,", '{name: "ty\\n",'))
    _cli_refuses(tmp_path, text, "invalid symbol name", field="symbols[5].name")


BAD_MODELS = [
    ("division-by-error", ("[0, Y2, Z]", "[0, Y2, Z - Y1/dz2]"), "divides by an expression that vanishes with dz2"),
    ("sqrt-of-error", ("[0, Y2, Z]", "[0, Y2, -Y1*sqrt(dz2)]"), "takes a power 1/2 of an expression that vanishes "
                                                                 "with dz2"),
    ("acos-of-nonsense", ("[0, Y2, Z]", "[0, Y2, Z + acos(2)]"), "is not real"),
    ("pole-at-default-axis", ("[0, Y2, Z]", "[0, Y2, Y1/X]"), "not finite at the nominal values (X = 0, Y1 = 50"),
    ("asin-at-one-of-error", ("[0, Y2, Z]", "[0, Y2, Z + asin(1 + dz2)]"), "takes asin at ±1"),
]


@pytest.mark.slow
@pytest.mark.parametrize("edit_,word", [b[1:] for b in BAD_MODELS], ids=[b[0] for b in BAD_MODELS])
def test_expressions_must_be_analytic_and_finite(tmp_path, edit_, word):
    text = edit(MACHINE, edit_)
    _cli_refuses(tmp_path, text, word, line=line_of(text, edit_[1]), field="chain[2].translate[2]")


def test_params_value_infinite_after_unit_conversion(tmp_path):
    m = tmp_path / "m.yaml"
    m.write_text(MACHINE)
    p = tmp_path / "p.yaml"
    p.write_text(edit(PARAMS, ("dx1: 3 um", "dx1: 1e308 m")))
    proc = run("eval", str(m), "--params", str(p))
    assert proc.returncode == 2, proc.stderr
    assert f"{p}:4: values.dx1: " in proc.stderr and "larger than" in proc.stderr, proc.stderr


@pytest.mark.slow
def test_huge_integer_nominal(tmp_path):
    text = edit(MACHINE, ("nominal: 50,", "nominal: " + "9" * 401 + ","))
    _cli_refuses(tmp_path, text, "larger than 1e+15", line=line_of(text, "nominal: 999"),
                 field="symbols.Y1.nominal")


@pytest.mark.slow
def test_chain_and_symbol_counts_bounded(tmp_path):
    from chaincomp.model.machine import MAX_CHAIN_ELEMENTS, MAX_SYMBOLS
    T = "  - {translate: [X, Y1, 0], label: component 1 (X slide)}\n"
    text = edit(MACHINE, (T, T * (MAX_CHAIN_ELEMENTS + 1)))
    _cli_refuses(tmp_path, text, f"{MAX_CHAIN_ELEMENTS + 4} chain elements (at most {MAX_CHAIN_ELEMENTS})",
                 line=line_of(text, "chain:"), field="chain")
    S = "  - {name: tz, role: constant, unit: mm, nominal: 40, meaning: Point z on component 2}\n"
    extra = "".join(f"  - {{name: k{i}, role: constant, unit: mm, nominal: 1}}\n" for i in range(MAX_SYMBOLS))
    text = edit(MACHINE, (S, S + extra))
    _cli_refuses(tmp_path, text, f"at most {MAX_SYMBOLS}", line=line_of(text, "symbols:"), field="symbols")


_YAML_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=12)
    | st.sampled_from(["5 um", "1e308 m", "-0 arcsec", "0170", "nan", ".inf", "3 furlong", "pi/2", "sin(X)"]),
    lambda kids: st.lists(kids, max_size=4) | st.dictionaries(st.text(max_size=8), kids, max_size=4),
    max_leaves=16)


def _load_random(tmp_path, doc: dict, key: str, entries, load):
    """Write ``doc`` (with ``entries`` under ``key``) and load it against the test machine:
    a value or ChaincompError, never another exception."""
    import yaml
    m = tmp_path / "m.yaml"
    m.write_text(MACHINE)
    doc = dict(doc)
    if entries:
        doc[key] = entries
    path = tmp_path / "f.yaml"
    path.write_text(yaml.safe_dump(doc, allow_unicode=True))
    try:
        return load(str(path), load_machine(str(m)))
    except ChaincompError:
        return None


@settings(max_examples=150, deadline=5000, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.dictionaries(st.sampled_from(["machine", "values", "description", "extra"]), _YAML_VALUES, max_size=4),
       st.dictionaries(st.sampled_from(["dx1", "ey1", "tx", "X", "nope"]), _YAML_VALUES, max_size=4))
@pytest.mark.slow
def test_params_loader_property_random_yaml(tmp_path, top, values):
    from chaincomp.model.params import load_params
    out = _load_random(tmp_path, top, "values", values, load_params) or {}
    for v in out.values():
        assert not isinstance(v, float) or abs(v) <= 1e15


@settings(max_examples=150, deadline=5000, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.dictionaries(st.sampled_from(["machine", "normal_bound", "tolerances", "description", "x"]), _YAML_VALUES,
                       max_size=4),
       st.dictionaries(st.sampled_from(["dx1", "ey1", "tx", "zz"]),
                       st.dictionaries(st.sampled_from(["bound", "distribution", "normal_bound", "q"]), _YAML_VALUES,
                                       max_size=3), max_size=3))
@pytest.mark.slow
def test_tolerances_loader_property_random_yaml(tmp_path, top, tols):
    from chaincomp.analysis.tolerances import load_tolerances
    _load_random(tmp_path, top, "tolerances", tols, load_tolerances)


@settings(max_examples=100, deadline=5000, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.dictionaries(st.sampled_from(["machine", "where", "formulas", "chain", "source"]), _YAML_VALUES, max_size=4),
       st.lists(st.dictionaries(st.sampled_from(["name", "of", "formula", "x"]), _YAML_VALUES, max_size=4), max_size=3))
@pytest.mark.slow
def test_check_loader_property_random_yaml(tmp_path, top, formulas):
    from chaincomp.analysis.check import load_formulas
    _load_random(tmp_path, top, "formulas", formulas, load_formulas)
