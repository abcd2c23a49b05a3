"""Every verb with a JSON mode keeps it on an error (docs/reference/errors.md, exit codes): the
one line on stderr, and one JSON object on stdout naming the verb, the kind, the exit code and the
line, so that a program reading the JSON is never handed an empty or partial document. Walked over
the whole command line, so a verb added later is covered."""

import argparse
import json

import pytest

from chaincomp.cli.main import build_parser, main


def _subparsers(parser):
    return next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)


def _json_switch(parser):
    """The option that turns a verb's output into JSON: --json, or --format json."""
    for a in parser._actions:
        if "--json" in a.option_strings:
            return ["--json"]
        if "--format" in a.option_strings and a.choices and "json" in a.choices:
            return ["--format", "json"]
    return None


def _json_verbs():
    """argv per verb with a JSON mode: every positional and required option a file that does not
    exist, then the JSON switch. Groups (thermal fit, ...) are walked too."""
    out = []
    pending = [([verb], parser) for verb, parser in _subparsers(build_parser()).choices.items()]
    while pending:
        words, parser = pending.pop(0)
        group = _subparsers(parser)
        if group is not None:
            pending += [(words + [verb], p) for verb, p in group.choices.items()]
            continue
        switch = _json_switch(parser)
        if switch is None:
            continue
        argv, files = list(words), 0
        for a in parser._actions:
            if (not a.option_strings and a.nargs != "?") or (a.option_strings and a.required):
                value = list(a.choices)[0] if a.choices else f"/nonexistent/{files}.yaml"
                argv += ([] if not a.option_strings else [a.option_strings[0]]) + [value]
                files += 1
        if files:
            out.append(pytest.param(argv + switch, id=" ".join(words)))
    return sorted(out, key=lambda p: p.id)


@pytest.mark.parametrize("argv", _json_verbs())
def test_a_refusal_in_json_mode_is_json(argv, capsys):
    code = main(argv)
    out, err = capsys.readouterr()
    assert code == 2 and err.count("\n") == 1, (code, err)
    got = json.loads(out)["error"]
    assert got["kind"] == "bad input" and got["exit"] == 2 and got["message"] == err.strip()
    assert err.startswith(f"chaincomp {got['verb']}: error: ")
