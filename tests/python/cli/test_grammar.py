"""The command line's grammar (docs/reference/grammar.md) held against the parser, walked verb by
verb: every option of every verb is in the page's table under its own name, with this verb
listed, the form of value it takes there listed and the same kind (a switch, one value,
repeatable) as in every other verb; nothing is in the table that no verb has. So an option name
given a second meaning in some verb fails until the page says so next to the first meaning (a
different value form or kind, or a verb missing from its row). Every verb is in the page's
table of verbs: one that prints a result has --format json, one that only writes files prints
nothing on stdout (its module read for print calls), and each JSON mode is among those
test_json_errors.py makes fail. Older spellings: each is in the deprecated table, warns naming
the new one and the release that removes it."""

from __future__ import annotations

import argparse
import ast
import inspect
import re
import sys
from pathlib import Path

import pytest

from chaincomp.cli.common import REMOVED_IN, DeprecatedAlias
from chaincomp.cli.main import build_parser
from helpers import ROOT

DOC = Path(ROOT) / "docs" / "reference" / "grammar.md"
# Verbs with a JSON mode that test_json_errors cannot make fail without input (it gives every
# required file as one that does not exist): where their JSON error is tested instead.
JSON_ERROR_ELSEWHERE = {
    "status": ("tests/python/runtime/test_status.py", "test_once_without_daemons_is_no_answer"),
}


def _cells(line: str) -> list[str]:
    """A Markdown table row's cells, '\\|' inside a cell kept as '|'."""
    return [c.strip().replace("\\|", "|") for c in re.split(r"(?<!\\)\|", line.strip())[1:-1]]


def _table(header: str) -> list[list[str]]:
    """The rows of the page's table whose first header cell is ``header``."""
    lines = DOC.read_text(encoding="utf-8").splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("|") and _cells(line)[0] == header)
    rows = []
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        rows.append(_cells(line))
    return rows


def _codes(cell: str) -> list[str]:
    return re.findall(r"`([^`]+)`", cell)


def _names(cell: str) -> list[str]:
    return [v.strip() for v in cell.split(",") if v.strip()]


def _verbs() -> dict[str, argparse.ArgumentParser]:
    """Every verb as the user types it ('thermal fit'), aliases left out."""
    out = {}
    pending = [((), build_parser())]
    while pending:
        words, parser = pending.pop(0)
        group = next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)
        if group is None:
            out[" ".join(words)] = parser
            continue
        pending += [(words + (name,), p) for name, p in group.choices.items() if p.prog.split()[-1] == name]
    return out


VERBS = _verbs()


def _kind(a: argparse.Action) -> str:
    if a.nargs == 0:
        return "switch"
    return "repeatable" if isinstance(a, argparse._AppendAction) else "value"


def _value(a: argparse.Action) -> str | None:
    """The value's form as --help shows it: the metavar, else the choices."""
    if a.nargs == 0:
        return None
    if isinstance(a.metavar, str):
        return a.metavar
    return "{" + ",".join(map(str, a.choices)) + "}" if a.choices else a.dest.upper()


def _options(parser) -> list[argparse.Action]:
    return [a for a in parser._actions if a.option_strings and "--help" not in a.option_strings
            and not isinstance(a, DeprecatedAlias)]


def _option_rows() -> dict[str, dict]:
    rows = {}
    for option, takes, meaning, verbs in _table("option"):
        names = tuple(_codes(option))
        kind = "switch" if takes == "—" else "repeatable" if "(repeatable)" in takes else "value"
        row = {"names": names, "values": _codes(takes), "kind": kind, "meaning": meaning, "verbs": _names(verbs)}
        for name in names:
            assert name not in rows, f"{name}: in two rows of {DOC.name}"
            rows[name] = row
    return rows


def test_the_page_and_the_parser_have_verbs_and_options():
    assert {"eval", "export", "thermal fit", "replay"} <= set(VERBS)
    assert len(_option_rows()) > 50 and len(_table("verb")) == len(VERBS)


def test_every_option_means_what_its_row_says_in_every_verb():
    rows, wrong = _option_rows(), []
    for verb, parser in VERBS.items():
        for a in _options(parser):
            row = rows.get(a.option_strings[0])
            if row is None:
                wrong.append(f"{verb} {a.option_strings[0]}: not in the table")
                continue
            if tuple(sorted(a.option_strings)) != tuple(sorted(row["names"])):
                wrong.append(f"{verb} {'/'.join(a.option_strings)}: the row spells it {'/'.join(row['names'])}")
            if verb not in row["verbs"]:
                wrong.append(f"{verb} {a.option_strings[0]}: {verb} is not among the row's verbs")
            if _kind(a) != row["kind"]:
                wrong.append(f"{verb} {a.option_strings[0]}: a {_kind(a)} here, a {row['kind']} in the table")
            if _value(a) is not None and _value(a) not in row["values"]:
                wrong.append(f"{verb} {a.option_strings[0]} {_value(a)}: not a form the row lists {row['values']}")
    assert not wrong, "\n".join(wrong)


def test_the_table_lists_only_what_the_verbs_take():
    seen = {}
    for verb, parser in VERBS.items():
        for a in _options(parser):
            for name in a.option_strings:
                seen.setdefault(name, {})[verb] = _value(a)
    stale = []
    for name, row in _option_rows().items():
        for verb in row["verbs"]:
            if verb not in seen.get(name, {}):
                stale.append(f"{name}: {verb} has no such option")
        used = set(seen.get(name, {}).values())
        stale += [f"{name}: no verb takes {v}" for v in row["values"] if v not in used]
        assert row["meaning"], name
    assert not stale, "\n".join(stale)


def _verb_rows() -> dict[str, tuple[str, str]]:
    return {verb: (prints, units) for verb, prints, units in _table("verb")}


def _prints_on_stdout(verb: str) -> list[str]:
    """print() calls without file=, and sys.stdout.write, in the module that runs the verb."""
    module = sys.modules[VERBS[verb].get_default("run").__module__]
    found = []
    for node in ast.walk(ast.parse(inspect.getsource(module))):
        if not isinstance(node, ast.Call):
            continue
        f = node.func
        if isinstance(f, ast.Name) and f.id == "print" and not any(k.arg == "file" for k in node.keywords):
            found.append(f"{module.__name__}:{node.lineno}")
        if isinstance(f, ast.Attribute) and f.attr == "write" and ast.unparse(f.value) == "sys.stdout":
            found.append(f"{module.__name__}:{node.lineno}")
    return found


@pytest.mark.parametrize("verb", sorted(VERBS))
def test_a_verb_that_prints_a_result_has_json_and_one_that_writes_prints_nothing(verb):
    rows = _verb_rows()
    assert verb in rows, f"{verb}: not in the table of verbs of {DOC.name}"
    prints, units = rows[verb]
    options = {s: a for a in _options(VERBS[verb]) for s in a.option_strings}
    fmt = options.get("--format")
    if prints == "result":
        assert fmt is not None and "json" in fmt.choices and fmt.default == "text", verb
        assert options["--json"].dest == fmt.dest and options["--json"].const == "json", verb
    elif prints == "document":   # report: the document's own formats
        assert fmt is not None and "json" not in fmt.choices, verb
    else:
        assert prints == "writes", f"{verb}: prints {prints!r}: expected result, document or writes"
        assert any(a.dest == "output" for a in VERBS[verb]._actions), f"{verb}: writes, but has no -o"
        if "prints the path" not in units:   # build: the library's path, for $(chaincomp build ...)
            assert not _prints_on_stdout(verb), f"{verb}: writes only, yet prints: {_prints_on_stdout(verb)}"
    assert (units == "yes") == ("--units" in options), f"{verb}: --units {'missing' if units == 'yes' else units}"


def test_every_verb_in_the_table_is_a_verb():
    assert set(_verb_rows()) == set(VERBS)


def test_every_json_mode_is_made_to_fail_in_json():
    from test_json_errors import _json_verbs
    covered = {p.id for p in _json_verbs()}
    json_verbs = {verb for verb, parser in VERBS.items()
                  if any("--format" in a.option_strings and "json" in (a.choices or ()) for a in _options(parser))}
    for verb, (path, test) in JSON_ERROR_ELSEWHERE.items():
        assert f"def {test}(" in (Path(ROOT) / path).read_text(encoding="utf-8"), (verb, path, test)
    assert json_verbs - covered - set(JSON_ERROR_ELSEWHERE) == set()


def _deprecated() -> dict[tuple[str, str], DeprecatedAlias]:
    return {(a.option_strings[0], verb): a for verb, parser in VERBS.items()
            for a in parser._actions if isinstance(a, DeprecatedAlias)}


def test_every_older_spelling_is_in_the_table_and_warns(capsys):
    rows = {(s, verb): (instead, removed) for spelling, verbs, instead, removed in _table("spelling")
            for s in _codes(spelling) for verb in _names(verbs)}
    actions = _deprecated()
    assert set(actions) == {k for k in rows if " " not in k[0]}   # 'X CONTROLLER': a value, below
    for (spelling, verb), action in actions.items():
        instead, removed = rows[(spelling, verb)]
        assert removed == REMOVED_IN
        new = action.replacement.split()[0]
        if new.startswith("--"):   # the new spelling is an option of the same verb
            assert new in {s for a in _options(VERBS[verb]) for s in a.option_strings}, (verb, spelling)
        assert instead.startswith(new), (verb, spelling, instead)
        action(VERBS[verb], argparse.Namespace(), "x", spelling)
        err = capsys.readouterr().err
        assert err == (f"chaincomp {verb}: warning: {spelling} is deprecated and will be removed in {REMOVED_IN}: "
                       f"use {action.replacement}\n")


@pytest.mark.parametrize("verb, controller, inputs", [("export", "marlin", ["m.yaml"]),
                                                     ("thermal stream", "siemens", ["m.yaml", "t.yaml", "l.csv"])])
def test_format_naming_a_controller_is_the_older_controller(verb, controller, inputs, capsys):
    args = VERBS[verb].parse_args([*inputs, "-o", "out", "--format", controller])
    assert (args.target, args.format) == (controller, "text")
    assert f"--format {controller} is deprecated and will be removed in {REMOVED_IN}: use --controller" in \
        capsys.readouterr().err
    args = VERBS[verb].parse_args([*inputs, "-o", "out", "--controller", controller, "--format", "json"])
    assert (args.target, args.format) == (controller, "json")
