"""Bad machine files, params files and --set values: each must give exit code 2 and one clear line.

Every case starts from a small valid machine (the ME220 X/Z example) or params file, makes one
edit, runs the CLI and checks that stderr names the file, the line of the edit, the field and
what is wrong, without a traceback. The expected line is computed here from where the edit
landed in the text, never copied from the program's output.
"""

import json
import subprocess

import pytest

from helpers import cli, line_of, run_cli


# A copy of configs/machines/me220_xz.yaml (kept here so edits and line numbers stay stable).
MACHINE = """\
# ME220 notes' X/Z two-slide example (a test copy).
name: me220_xz
description: ME220 notes' X/Z two-slide example with positioning, yaw and pitch errors
length_unit: mm
rotation_sense: right_hand
error_block_order: txyz

symbols:
  - {name: X,  role: axis, unit: mm, limits: [-200, 200], meaning: X slide position}
  - {name: Z,  role: axis, unit: mm, limits: [-150, 150], meaning: Z slide position}
  - {name: Y1, role: constant, unit: mm, nominal: 50, meaning: Fixed Y offset of component 1}
  - {name: Y2, role: constant, unit: mm, nominal: 30, meaning: Fixed Y offset of component 2}
  - {name: tx, role: constant, unit: mm, nominal: 20, meaning: Point x on component 2}
  - {name: ty, role: constant, unit: mm, nominal: 10, meaning: Point y on component 2}
  - {name: tz, role: constant, unit: mm, nominal: 40, meaning: Point z on component 2}
  - {name: dx1, role: error, unit: um,     meaning: Positional error of component 1 in x}
  - {name: ey1, role: error, unit: arcsec, meaning: Yaw error of component 1}
  - {name: ez1, role: error, unit: arcsec, meaning: Pitch error of component 1}
  - {name: dz2, role: error, unit: um,     meaning: Positional error of component 2 in z}
  - {name: ey2, role: error, unit: arcsec, meaning: Yaw error of component 2}

chain:
  - {translate: [X, Y1, 0], label: component 1 (X slide)}
  - {errors: {dx: dx1, ey: ey1, ez: ez1}, label: component 1 errors}
  - {translate: [0, Y2, Z], label: component 2 (Z slide)}
  - {errors: {dz: dz2, ey: ey2}, label: component 2 errors}

tool:
  point: [tx, ty, tz]
"""

PARAMS = """\
# Error values for the test copy of me220_xz.
machine: me220_xz
values:
  dx1: 3 um
  ey1: 5 arcsec
  ez1: -4 arcsec
  dz2: -2 um
  ey2: 3 arcsec
"""

T0 = "  - {translate: [X, Y1, 0], label: component 1 (X slide)}\n"  # chain[0], to insert after


def edit(text: str, *edits: tuple[str, str]) -> str:
    for old, new in edits:
        assert text.count(old) == 1, f"edit target not unique: {old!r}"
        text = text.replace(old, new)
    return text


def run(*args: str) -> subprocess.CompletedProcess:
    """In this process (cli.main.main): the cases below as a process each cost ~1 s of start-up."""
    return cli(*args, check=False)


def check(proc: subprocess.CompletedProcess, where: str, field: str | None, word: str) -> None:
    err = proc.stderr
    assert proc.returncode == 2, f"exit {proc.returncode}\nstderr:\n{err}"
    assert "Traceback" not in err, err
    assert len(err.strip().splitlines()) == 1, f"expected one line on stderr:\n{err}"
    # nothing on stdout but, in a JSON mode, the error as JSON (the same line)
    if proc.stdout:
        assert json.loads(proc.stdout)["error"]["message"] == err.strip(), proc.stdout
    expected = where + (f" {field}: " if field else "")
    assert expected in err, f"expected {expected!r} in:\n{err}"
    assert word in err, f"expected {word!r} in:\n{err}"


def case(cid, edits, at, field, word, verb="eval"):
    """One bad machine file: ``edits`` applied to MACHINE, error expected on the line of ``at``."""
    return pytest.param(edits, at, field, word, verb, id=cid)


MACHINE_CASES = [
    case("unknown-symbol-in-expression",
         [("[X, Y1, 0]", "[X, Y9, 0]")], "[X, Y9, 0]", "chain[0].translate[1]", "unknown symbol 'Y9'",
         verb="derive"),
    case("unknown-function-in-expression",
         [("[0, Y2, Z]", "[0, Y2, cosh(Z)]")], "cosh(Z)", "chain[2].translate[2]", "unknown function 'cosh'"),
    case("unparsable-expression",
         [("[X, Y1, 0]", "[X, 'Y1 + (2', 0]")], "'Y1 + (2'", "chain[0].translate[1]", "cannot parse",
         verb="derive"),
    case("empty-expression",
         [("[0, Y2, Z]", "[0, Y2, '']")], "[0, Y2, '']",
         "chain[2].translate[2]", "empty expression"),
    case("unknown-unit",
         [("{name: X,  role: axis, unit: mm,", "{name: X,  role: axis, unit: furlong,")], "unit: furlong",
         "symbols.X.unit", "unknown unit 'furlong'"),
    case("duplicate-symbol-name",
         [("{name: Y2,", "{name: Y1,")], "{name: Y1, role: constant, unit: mm, nominal: 30",
         "symbols[3].name", "duplicate symbol name 'Y1'"),
    case("wrong-role",
         [("{name: Z,  role: axis,", "{name: Z,  role: slide,")], "role: slide", "symbols.Z.role",
         "unknown role 'slide'"),
    case("wrong-element-kind",
         [(T0, T0 + "  - {spin: z, angle: X}\n")], "{spin: z", "chain[1]", "spin", verb="derive"),
    case("two-kinds-in-one-element",
         [("{translate: [0, Y2, Z],", "{translate: [0, Y2, Z], rotate: z, angle: 0,")], "rotate: z",
         "chain[2]", "found rotate, translate"),
    case("missing-tool",
         [("tool:\n  point: [tx, ty, tz]\n", "")], "name: me220_xz", "(top level)",
         "missing required field 'tool'"),
    case("missing-tool-point",
         [("  point: [tx, ty, tz]\n", "  direction: [0, 0, 1]\n")], "tool:", "tool",
         "missing required field 'point'"),
    case("tool-point-two-components",
         [("point: [tx, ty, tz]", "point: [tx, ty]")], "point:", "tool.point",
         "three expressions [x, y, z], got a list of 2 items"),
    case("non-numeric-nominal",
         [("nominal: 50,", "nominal: fifty,")], "nominal: fifty", "symbols.Y1.nominal", "expected a number"),
    case("infinite-nominal",
         [("nominal: 50,", "nominal: .inf,")], "nominal: .inf", "symbols.Y1.nominal", "finite"),
    case("nominal-on-error-symbol",
         [("{name: dx1, role: error, unit: um,", "{name: dx1, role: error, unit: um, nominal: 1,")],
         "nominal: 1,", "symbols.dx1.nominal", "no nominal"),
    case("yaml-syntax-error",
         [("description: ME220", "description: yaw: pitch ME220")], "description:", None,
         "YAML syntax error"),
    case("yaml-tab-indent",
         [("  point: [tx, ty, tz]", "\tpoint: [tx, ty, tz]")], "\tpoint", None, "YAML syntax error"),
    case("duplicate-yaml-key",
         [("rotation_sense: right_hand\n", "rotation_sense: right_hand\nlength_unit: um\n")],
         "length_unit: um", "length_unit", "duplicate key"),
    case("duplicate-yaml-key-in-flow-mapping",
         [("{name: ty, role: constant, unit: mm,", "{name: ty, role: constant, unit: mm, unit: um,")],
         "{name: ty,", "unit", "duplicate key"),
    case("unhashable-yaml-key",
         [("error_block_order: txyz\n", "error_block_order: txyz\n? [a, b]\n: 1\n")], "? [a, b]", None,
         "mapping key must be text or a number"),
    case("reserved-symbol-name",
         [("{name: ty,", "{name: int,")], "{name: int,", "symbols[5].name", "reserved"),
    case("python-keyword-symbol-name",
         [("{name: ty,", "{name: yield,"), ("[tx, ty, tz]", "[tx, yield, tz]")], "{name: yield,",
         "symbols[5].name", "reserved"),
    case("symbol-name-shadowing-parser",
         [("{name: ty,", "{name: Integer,"), ("[tx, ty, tz]", "[tx, Integer, tz]")], "{name: Integer,",
         "symbols[5].name", "reserved"),
    case("invalid-symbol-name",
         [("{name: ty,", "{name: 2ty,")], "{name: 2ty,", "symbols[5].name", "invalid symbol name"),
    case("constant-without-nominal",
         [("{name: Y1, role: constant, unit: mm, nominal: 50,", "{name: Y1, role: constant, unit: mm,")],
         "{name: Y1,", "symbols.Y1", "needs a 'nominal'"),
    case("axis-without-limits",
         [("limits: [-200, 200], ", "")], "{name: X,", "symbols.X", "limits"),
    case("limits-low-not-below-high",
         [("limits: [-150, 150]", "limits: [150, 150]")], "limits: [150, 150]", "symbols.Z.limits",
         "must be below"),
    case("limits-one-value",
         [("limits: [-150, 150]", "limits: [150]")], "limits: [150]", "symbols.Z.limits",
         "expected [low, high], got a list of 1 item"),
    case("translate-two-components",
         [("[X, Y1, 0]", "[X, Y1]")], "[X, Y1]", "chain[0].translate", "three expressions"),
    case("rotation-axis-w",
         [(T0, T0 + "  - {rotate: w, angle: 0}\n")], "{rotate: w", "chain[1].rotate", "x, y or z"),
    case("rotation-without-angle",
         [(T0, T0 + "  - {rotate: z}\n")], "{rotate: z}", "chain[1]", "missing required field 'angle'"),
    case("error-block-unknown-key",
         [("{dz: dz2, ey: ey2}", "{dw: dz2, ey: ey2}")], "{dw: dz2", "chain[3].errors.dw",
         "unknown field 'dw'"),
    case("error-block-order-not-permutation",
         [("{errors: {dz: dz2, ey: ey2},", "{errors: {dz: dz2, ey: ey2}, order: tzy,")], "order: tzy",
         "chain[3].order", "permutation"),
    case("top-level-order-not-permutation",
         [("error_block_order: txyz", "error_block_order: txyy")], "error_block_order:",
         "error_block_order", "permutation"),
    case("error-block-without-order",
         [("error_block_order: txyz\n", "")], "{errors: {dx: dx1", "chain[1].order", "order",
         verb="derive"),
    case("bad-element-sense",
         [("{errors: {dz: dz2, ey: ey2},", "{errors: {dz: dz2, ey: ey2}, sense: [left_hand],")],
         "sense: [left_hand]", "chain[3].sense", "sense must be one of"),
    case("rotation-sense-not-text",
         [("rotation_sense: right_hand", "rotation_sense: [right_hand]")], "rotation_sense:",
         "rotation_sense", "rotation_sense must be one of"),
    case("length-unit-not-a-length",
         [("length_unit: mm", "length_unit: arcsec")], "length_unit:", "length_unit", "length unit"),
    case("length-unit-not-text",
         [("length_unit: mm", "length_unit: {mm: 1}")], "length_unit:", "length_unit", "length unit"),
    case("unknown-top-level-field",
         [("length_unit: mm\n", "length_unit: mm\ncolour: red\n")], "colour:", "(top level).colour",
         "unknown field 'colour'"),
    case("unknown-symbol-field",
         [("{name: tz, role: constant,", "{name: tz, colour: red, role: constant,")], "{name: tz,",
         "symbols[6].colour", "unknown field 'colour'"),
    case("declared-but-unused-symbol",
         [("  - {name: dx1,", "  - {name: W, role: constant, unit: mm, nominal: 1}\n  - {name: dx1,")],
         "{name: W,", "symbols.W", "never used", verb="derive"),
    case("both-chain-and-loop",
         [("\ntool:\n", "\nloop:\n  tool: [{translate: [X, 0, 0]}]\n  workpiece: [{translate: [0, 0, Z]}]"
           "\n\ntool:\n")], "loop:", "loop", "exactly one of 'chain'"),
    case("neither-chain-nor-loop",
         [(MACHINE[MACHINE.index("chain:"):MACHINE.index("tool:")], "")], "name: me220_xz", "chain",
         "exactly one of 'chain'"),
    case("loop-without-workpiece",
         [("chain:\n", "loop:\n  tool:\n")], "loop:", "loop", "missing required field 'workpiece'"),
    case("empty-chain",
         [(MACHINE[MACHINE.index("chain:"):MACHINE.index("tool:")], "chain: []\n\n")], "chain:", "chain",
         "non-empty list"),
]


@pytest.mark.parametrize("edits,at,field,word,verb", MACHINE_CASES)
def test_bad_machine(tmp_path, edits, at, field, word, verb):
    text = edit(MACHINE, *edits)
    path = tmp_path / "bad.yaml"
    path.write_text(text, encoding="utf-8")
    args = [verb, str(path)] + (["--json"] if verb == "eval" else ["--format", "json"])
    proc = run(*args)
    check(proc, f"{path}:{line_of(text, at)}:", field, word)


@pytest.mark.slow
def test_a_bad_machine_exits_2_from_a_process(tmp_path):
    """The exit path of a real process, for one case (the others run in this process)."""
    edits, at, field, word, verb = MACHINE_CASES[0].values
    text = edit(MACHINE, *edits)
    path = tmp_path / "bad.yaml"
    path.write_text(text, encoding="utf-8")
    check(run_cli(verb, str(path), "--json", check=False), f"{path}:{line_of(text, at)}:", field, word)


def test_duplicate_symbol_names_first_line(tmp_path):
    """The duplicate-name message also points back to the first declaration."""
    text = edit(MACHINE, ("{name: Y2,", "{name: Y1,"))
    path = tmp_path / "bad.yaml"
    path.write_text(text, encoding="utf-8")
    proc = run("eval", str(path), "--json")
    second = line_of(text, "{name: Y1, role: constant, unit: mm, nominal: 30")
    first = line_of(text, "{name: Y1, role: constant, unit: mm, nominal: 50")
    check(proc, f"{path}:{second}:", "symbols[3].name", f"first declared on line {first}")


def test_nonexistent_machine_file(tmp_path):
    path = tmp_path / "no_such_machine.yaml"
    proc = run("eval", str(path), "--json")
    check(proc, f"{path}:", None, "cannot read file")


def test_machine_file_not_utf8(tmp_path):
    data = MACHINE.encode("utf-8").replace(b"Point y on", b"Point y \xff on")
    path = tmp_path / "bad.yaml"
    path.write_bytes(data)
    check(run("eval", str(path), "--json"), f"{path}:{line_of(MACHINE, 'Point y on')}:", None, "UTF-8")


def test_machine_file_control_character(tmp_path):
    text = edit(MACHINE, ("Point z on", "Point z \x07on"))
    path = tmp_path / "bad.yaml"
    path.write_text(text, encoding="utf-8")
    check(run("eval", str(path), "--json"), f"{path}:{line_of(text, 'Point z')}:", None, "character")


def test_machine_file_not_a_mapping(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("# a list, not a machine\n- name: me220_xz\n", encoding="utf-8")
    check(run("eval", str(path), "--json"), f"{path}:2:", "(top level)", "expected a mapping")


# ----------------------------------------------------------------------------- params and --set

def pcase(cid, edits, at, field, word):
    """One bad params file: ``edits`` applied to PARAMS, error expected on the line of ``at``."""
    return pytest.param(edits, at, field, word, id=cid)


PARAMS_CASES = [
    pcase("unknown-symbol", [("  dz2: -2 um\n", "  dz2: -2 um\n  dq7: 1 um\n")], "dq7:", "values.dq7",
          "unknown symbol 'dq7'"),
    pcase("wrong-unit-kind", [("dx1: 3 um", "dx1: 3 arcsec")], "dx1:", "values.dx1", "angle unit"),
    pcase("unknown-unit", [("dz2: -2 um", "dz2: -2 furlong")], "dz2:", "values.dz2", "unknown unit"),
    pcase("non-finite-value", [("dx1: 3 um", "dx1: .nan")], "dx1:", "values.dx1", "finite"),
    pcase("infinite-value-with-unit", [("dx1: 3 um", "dx1: 1e999 um")], "dx1:", "values.dx1", "finite"),
    pcase("not-a-number", [("ey1: 5 arcsec", "ey1: [5, arcsec]")], "ey1:", "values.ey1", "expected a number"),
    pcase("text-not-a-number", [("ey1: 5 arcsec", "ey1: five arcsec")], "ey1:", "values.ey1",
          "expected a number"),
    pcase("params-for-another-machine", [("machine: me220_xz", "machine: five_axis_ac")], "machine:",
          "machine", "params are for machine 'five_axis_ac'"),
    pcase("axis-in-params", [("values:\n", "values:\n  X: 10\n")], "X: 10", "values.X", "is an axis"),
    pcase("unknown-params-field", [("values:\n", "valeus: {}\nvalues:\n")], "valeus:", "valeus",
          "unknown field 'valeus'"),
    pcase("values-not-a-mapping", [(PARAMS[PARAMS.index("values:"):], "values: [dx1, ey1]\n")], "values:",
          "values", "mapping"),
    pcase("duplicate-params-key", [("  ey2: 3 arcsec\n", "  ey2: 3 arcsec\n  dx1: 4 um\n")], "dx1: 4",
          "dx1", "duplicate key"),
    pcase("params-yaml-syntax-error", [("ez1: -4 arcsec", "ez1: -4 arcsec: x")], "ez1:", None,
          "YAML syntax error"),
]


@pytest.mark.parametrize("edits,at,field,word", PARAMS_CASES)
def test_bad_params(tmp_path, edits, at, field, word):
    machine = tmp_path / "me220_xz.yaml"
    machine.write_text(MACHINE, encoding="utf-8")
    text = edit(PARAMS, *edits)
    path = tmp_path / "bad-params.yaml"
    path.write_text(text, encoding="utf-8")
    proc = run("eval", str(machine), "--params", str(path), "--json")
    check(proc, f"{path}:{line_of(text, at)}:", field, word)


def test_nonexistent_params_file(tmp_path):
    machine = tmp_path / "me220_xz.yaml"
    machine.write_text(MACHINE, encoding="utf-8")
    path = tmp_path / "no_such_params.yaml"
    check(run("eval", str(machine), "--params", str(path), "--json"), f"{path}:", None, "cannot read file")


@pytest.mark.parametrize("item,word", [
    pytest.param("dx1", "NAME=VALUE", id="no-equals"),
    pytest.param("dq7=1", "unknown symbol 'dq7'", id="unknown-name"),
    pytest.param("=1", "unknown symbol ''", id="empty-name"),
    pytest.param("dx1=3 arcsec", "angle unit", id="wrong-unit-kind"),
    pytest.param("dx1=", "expected a number", id="empty-value"),
    pytest.param("dx1=nan", "expected a number", id="nan-text"),
    pytest.param("dx1=1e999", "finite", id="overflow"),
    pytest.param("dx1=3 furlong", "unknown unit", id="unknown-unit"),
])
def test_bad_set(tmp_path, item, word):
    machine = tmp_path / "me220_xz.yaml"
    machine.write_text(MACHINE, encoding="utf-8")
    proc = run("eval", str(machine), "--set", item, "--json")
    check(proc, "error: --set", None, word)
