"""One command line: every verb's parser walked, the shared options' names and defaults held
against the list below (written here, not read from the code), the older spellings kept."""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from chaincomp.cli.common import hoist_machine_option
from chaincomp.errors import ChaincompError
from chaincomp.cli.main import build_parser, main
from helpers import ROOT as HELPERS_ROOT

ROOT = Path(HELPERS_ROOT)
M = str(ROOT / "configs/machines/five_axis_ac.yaml")

# The shared ideas: option -> what every verb that has it must agree on.
SEED_DEFAULT = 1
FORMAT_DEFAULT = "text"          # wherever json is one of the formats
MODEL_DEFAULT = "1"              # budget and plot: 1, 2 or exact
# Verbs without a machine file as their first argument, and why.
NO_MACHINE_FIRST = {
    "iso230-2": "reads laser runs only",
    "status": "listens to the daemons on the bus; its machine files (any number) name the daemons' axes",
    "generate": "takes several machine files (all positional)",
    "import-urdf": "reads a URDF and writes the machine file",
}
UNITS_CHOICES, UNITS_DEFAULT = ("people", "internal"), "people"   # µm/arcsec, or mm/rad
UNITS_VERBS = {"eval", "plot", "identify", "budget"}   # verbs that print errors for people


def _verbs() -> dict[str, argparse.ArgumentParser]:
    """Every verb; a group's (thermal) as 'thermal fit', 'thermal check'."""
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    out = {}
    for verb, p in sub.choices.items():
        group = [a for a in p._actions if isinstance(a, argparse._SubParsersAction)]
        out.update({f"{verb} {v}": q for v, q in group[0].choices.items()} if group else {verb: p})
    return out


VERBS = _verbs()


def _options(p: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    return {s: a for a in p._actions for s in a.option_strings}


def test_there_are_verbs():
    assert {"derive", "eval", "budget", "plot", "replay", "laser-to-params"} <= set(VERBS)


@pytest.mark.parametrize("verb", sorted(VERBS))
def test_every_option_and_argument_has_help(verb):
    for a in VERBS[verb]._actions:
        if isinstance(a, argparse._HelpAction):
            continue
        assert a.help and a.help.strip(), f"{verb}: {a.option_strings or a.dest} has no help text"
        # the example of a slip: an article before a vowel
        assert not re.search(r"\ba [aeiou]", a.help), f"{verb}: {a.help!r}"


@pytest.mark.parametrize("verb", sorted(VERBS))
def test_shared_options_have_the_same_names_and_defaults(verb):
    opts = _options(VERBS[verb])
    if "--seed" in opts:
        assert opts["--seed"].default == SEED_DEFAULT, verb
        assert opts["--seed"].type("4294967295") == 2**32 - 1
    if "--format" in opts and "json" in (opts["--format"].choices or ()):
        assert opts["--format"].default == FORMAT_DEFAULT, verb
    if "--json" in opts:   # the older spelling of --format json, in every verb
        assert "--format" in opts and opts["--json"].dest == opts["--format"].dest == "format", verb
        assert opts["--json"].const == "json", verb
        assert opts["--format"].default == FORMAT_DEFAULT and "json" in opts["--format"].choices, verb
    if "--assume-zero" in opts:
        a = opts["--assume-zero"]
        assert isinstance(a, argparse._AppendAction) and a.default == [] and a.metavar == "E1,E2", verb
    for name in ("--params", "--set"):   # values: the same everywhere
        if name in opts:
            assert opts[name].metavar in ("P.yaml", "NAME=VALUE", "AXIS=VALUE"), (verb, name)
    if "--units" in opts:
        assert tuple(opts["--units"].choices) == UNITS_CHOICES and opts["--units"].default == UNITS_DEFAULT, verb
    if verb in UNITS_VERBS:
        assert "--units" in opts, verb
    if "--order" in opts and verb in ("budget", "plot"):
        assert opts["--order"].default == MODEL_DEFAULT
        assert opts["--order"].type("exact") == "exact"
        assert opts["--order"].type("2") == "2"


@pytest.mark.parametrize("verb", sorted(set(VERBS) - set(NO_MACHINE_FIRST)))
def test_the_machine_file_is_the_first_positional(verb):
    positionals = [a for a in VERBS[verb]._actions if not a.option_strings]
    assert positionals and positionals[0].dest == "machine", verb
    assert positionals[0].metavar == "MACHINE.yaml"
    machine_opt = _options(VERBS[verb]).get("--machine")
    assert machine_opt is None or not machine_opt.required, verb


def _parse(*argv):
    return build_parser().parse_args(list(argv))


def test_replay_takes_the_machine_first_or_as_machine(capsys):
    new = _parse("replay", M, "in.lcmlog", "--params", "p.yaml")
    build_parser()   # the verbs register which of them once took --machine
    old = _parse(*hoist_machine_option(["replay", "in.lcmlog", "--machine", M, "--params", "p.yaml"]))
    assert "--machine is deprecated" in capsys.readouterr().err
    # options before the log: the file is a required positional, so argparse never hands the
    # machine to IN.lcmlog (it did while the machine was an optional positional)
    between = _parse("replay", M, "--model", "lib.so", "in.lcmlog", "--params", "p.yaml")
    for a in (new, old, between):
        assert (a.machine, a.input) == (M, "in.lcmlog")


def test_replay_refuses_the_machine_twice_or_never(tmp_path, capsys):
    log = tmp_path / "in.lcmlog"
    log.write_bytes(b"")
    assert main(["replay", M, str(log), "--machine", M, "--params", "p.yaml"]) == 2
    warning, err = capsys.readouterr().err.splitlines()   # --machine is deprecated: a warning, then the error
    assert warning.startswith("chaincomp replay: warning: --machine is deprecated")
    assert "error: unrecognized arguments" in err
    assert main(["replay", str(log), "--params", "p.yaml"]) == 2
    assert "the following arguments are required: IN.lcmlog" in capsys.readouterr().err


def test_laser_to_params_takes_the_machine_first_or_as_machine(capsys):
    common = ("--error", "EXX", "-o", "out.yaml")
    new = _parse("laser-to-params", M, "runs.csv", *common)
    build_parser()
    old = _parse(*hoist_machine_option(["laser-to-params", "runs.csv", "--machine", M, *common]))
    assert "--machine is deprecated" in capsys.readouterr().err
    for a in (new, old):
        assert (a.machine, a.runs) == (M, "runs.csv")


@pytest.mark.parametrize("verb", ["eval", "check", "identify", "protocol", "budget", "iso230-2", "derive"])
def test_json_is_format_json(verb):
    opts = _options(VERBS[verb])
    assert "--json" in opts and opts["--format"].default == "text"
    first = {"iso230-2": ["runs.csv"], "check": [M, "f.yaml"], "identify": [M, "m.csv"]}.get(verb, [M])
    assert _parse(verb, *first, "--json").format == "json"
    assert _parse(verb, *first, "--format", "json").format == "json"
    assert _parse(verb, *first).format == "text"


@pytest.mark.parametrize("old, new", [("first", "1"), ("second", "2"), ("exact", "exact"),
                                      ("second-first", "2-1"), ("exact-first", "exact-1"),
                                      ("exact-second", "exact-2")])
def test_plot_model_spellings(old, new):
    a = _parse("plot", M, "--model", old)
    b = _parse("plot", M, "--order", new)
    assert a.model == b.model == new


def test_plot_and_budget_refuse_an_unknown_model(capsys):
    for verb in ("plot", "budget"):
        assert main([verb, M, "--order", "3"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "--order" in err and "expected one of 1, 2, exact" in err


def test_seeds_agree_between_verbs():
    seeds = {v: _options(p)["--seed"].default for v, p in VERBS.items() if "--seed" in _options(p)}
    assert {"budget", "testvectors", "simulate-measurements", "simulate-calibration"} <= set(seeds)
    assert set(seeds.values()) == {SEED_DEFAULT}


def test_setups_has_both_spellings():
    assert _parse("simulate-measurements", M, "-o", "x.csv", "--set-ups", "grid:3").setups == "grid:3"
    assert _parse("simulate-measurements", M, "-o", "x.csv", "--setups", "grid:3").setups == "grid:3"


def _pyproject_version() -> str:
    # pyproject.toml names __init__.py as the source (dynamic); a literal there would be read first
    return tomllib.loads((ROOT / "codegen/pyproject.toml").read_text())["project"].get("version") or \
        re.search(r'__version__ = "([^"]+)"', (ROOT / "codegen/chaincomp/__init__.py").read_text()).group(1)


@pytest.mark.slow
def test_version():
    out = subprocess.run([sys.executable, "-m", "chaincomp.cli.main", "--version"], capture_output=True,
                         text=True, check=True).stdout
    assert out == f"chaincomp {_pyproject_version()}\n"


def test_top_level_help_lists_every_verb_on_one_line():
    text = build_parser().format_help()
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    for verb in dict.fromkeys(v.split()[0] for v in VERBS):   # a group (thermal) once
        help_text = next(c.help for c in sub._choices_actions if c.dest == verb)
        assert re.search(rf"^    {re.escape(verb)} +{re.escape(help_text)}$", text, re.M), verb
    assert "--version" in text


@pytest.mark.parametrize("program", ["chaincompd", "chaincomp_replay"])
def test_the_programs_version_is_the_package_version(program):
    from chaincomp.emit.buildtree import binary
    try:
        path = binary(program)
    except ChaincompError as exc:   # no C++ build here
        pytest.skip(str(exc))
    out = subprocess.run([path, "--version"], capture_output=True, text=True, timeout=30)
    assert (out.returncode, out.stdout) == (0, f"{program} {_pyproject_version()}\n")


COMPLETION = ROOT / "tools/chaincomp-completion.bash"


def test_the_bash_completion_is_up_to_date():
    from chaincomp.cli.completion import bash_script
    assert COMPLETION.read_text() == bash_script(), \
        "regenerate: python -m chaincomp.cli.completion > tools/chaincomp-completion.bash"


def _complete(*words: str) -> list[str]:
    """What bash offers after `words` (the last one being typed), with the script sourced."""
    line = " ".join(f"'{w}'" for w in words)
    script = (f"source '{COMPLETION}'; COMP_WORDS=({line}); COMP_CWORD=$(({len(words)} - 1)); _chaincomp; "
              "printf '%s\\n' \"${COMPREPLY[@]}\"")
    out = subprocess.run(["bash", "--norc", "-c", script], capture_output=True, text=True, timeout=30, check=True)
    return out.stdout.split()


def test_bash_completes_verbs_options_and_values():
    assert _complete("chaincomp", "simulate-") == ["simulate-measurements", "simulate-log", "simulate-calibration",
                                                   "simulate-thermal"]
    assert _complete("chaincomp", "thermal", "") == ["fit", "check", "stream"]   # a group's verbs
    assert _complete("chaincomp", "--ver") == ["--version"]
    assert _complete("chaincomp", "budget", M, "--se") == ["--set", "--seed"]
    assert _complete("chaincomp", "budget", M, "--order", "") == ["1", "2", "exact"]
    assert _complete("chaincomp", "plot", M, "--order", "e") == ["exact", "exact-1", "exact-2"]
    assert _complete("chaincomp", "eval", M, "--format", "") == ["text", "json"]
    assert _complete("chaincomp", "replay", "--mach") == []   # a deprecated spelling is offered no more
    assert _complete("chaincomp", "eval", "") == []   # a file name: bash's own completion (-o default)
