"""Every verb's options with bad values: exit 2, one line on stderr naming the option, no
traceback, and no input touched (issue 14). The verbs run in-process (chaincomp.cli.main.main)
on copies of bundled files written into tmp_path, so that a verb that wrongly writes over an
input damages only the copy and the test sees it."""

from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import subprocess
import sys

import pytest
from helpers import PARAMS, ROOT, machine_path

from chaincomp.cli import main as cli

CONFIGS = os.path.join(ROOT, "configs")


@pytest.fixture
def ws(tmp_path):
    """Paths of a workspace: copies of bundled files, a non-UTF-8 file, a link to an input,
    a folder, and a path in a folder that does not exist."""
    copies = {
        "ah": machine_path("angle_head"), "ahp": os.path.join(PARAMS, "angle_head-fig3.yaml"),
        "five": machine_path("five_axis_ac"), "fivet": os.path.join(CONFIGS, "tolerances", "five_axis_ac.yaml"),
        "check": os.path.join(CONFIGS, "checks", "paper_table2.yaml"),
    }
    p = {k: str(shutil.copy(v, tmp_path / f"{k}.yaml")) for k, v in copies.items()}
    (tmp_path / "latin1.yaml").write_bytes("machine: caf\xe9\n".encode("latin-1"))
    p["latin1"] = str(tmp_path / "latin1.yaml")
    os.symlink(p["ah"], tmp_path / "link.yaml")
    p["link"] = str(tmp_path / "link.yaml")
    (tmp_path / "folder").mkdir()
    p["folder"] = str(tmp_path / "folder")
    p["missing"] = str(tmp_path / "missing.yaml")
    p["nodir"] = str(tmp_path / "no" / "such" / "out.png")
    p["out"] = str(tmp_path / "out.png")
    return p


def _snapshot(folder: str) -> dict[str, str]:
    out = {}
    for dirpath, _, files in os.walk(folder):
        for f in files:
            path = os.path.join(dirpath, f)
            with open(path, "rb") as fh:
                out[os.path.relpath(path, folder)] = hashlib.sha256(fh.read()).hexdigest()
    return out


def run(capsys, argv: list[str]) -> tuple[int, str, str]:
    code = cli.main(argv)
    out, err = capsys.readouterr()
    return code, out, err


# Each case: the command line ({name} takes a workspace path) and the word the message must hold.
FILE = "file"
NUMBERS = ["nan", "inf", "-inf", "1e400", "", "x", "1_0", "\u0661"]   # the last two: float() takes them
INTEGERS = NUMBERS + ["1.5", "1e3", "0x10"]


def _opt(base: list[str], option: str, values, word: str | None = None):
    """Cases of option with each value; the message names the option, or `word`, or with
    word=FILE the value itself (a file's errors name the file)."""
    return [(base + [option, v], v if word == FILE else word or option) for v in values]


AH = ["{ah}"]
CASES = (
    # derive, check, report, generate: the order
    _opt(["derive"] + AH, "--order", ["0", "-1", "5", "99999999999999999999999"] + INTEGERS)
    + _opt(["check"] + AH + ["{check}"], "--order", ["0", "5", "nan"])
    + _opt(["report"] + AH, "--order", ["0", "5", "inf"])
    + _opt(["generate"] + AH + ["-o", "{folder}"], "--order", ["0", "5", "nan"])
    # protocol
    + _opt(["protocol"] + AH, "--angles", ["nan,inf", "1e400", "", "0,,90", "0,x", "1000",
                                           ",".join(str(a) for a in range(0, 360, 10))])
    + _opt(["protocol"] + AH, "--order", ["0", "2", "nan"])
    + _opt(["protocol"] + AH, "--measure", ["", "w", "x,,y"])
    + _opt(["protocol"] + AH, "--assume-zero", ["NOPE", "Ap", "ThetaAs,"])
    + _opt(["protocol"] + AH, "--prefer", ["NOPE"])
    + _opt(["protocol"] + AH, "--set", ["Ap=10", "Q=1"])
    # eval
    + _opt(["eval"] + AH, "--set", ["G=nan", "G=inf", "G=", "Q=1", "G=1e400"])
    + _opt(["eval"] + AH, "--params", ["{missing}", "{latin1}", "{folder}"], FILE)
    # testvectors
    + _opt(["testvectors"] + AH + ["-o", "{out}"], "--count", ["0", "-1", "1001", "10000000000"] + INTEGERS)
    + _opt(["testvectors"] + AH + ["-o", "{out}"], "--seed", ["-1", str(2**32), "nan", "1e3"])
    + _opt(["testvectors"] + AH, "-o", ["{ah}", "{link}", "{folder}", "{nodir}"])
    # plot
    + _opt(["plot"] + AH + ["-o", "{out}"], "--grid", ["1", "0", "-1", "1001"] + INTEGERS)
    + _opt(["plot"] + AH + ["-o", "{out}"], "--range", ["nan:1", "-inf:inf", "1:0", "x", "1:2:3", "1e400:1"])
    + _opt(["plot"] + AH + ["-o", "{out}"], "--range2", ["0:nan", "5:5"])
    + _opt(["plot"] + AH + ["-o", "{out}"], "--over", ["Ap,Ap", "Ap,Q", "Ap"])
    + _opt(["plot"] + AH + ["--params", "{ahp}"], "-o", ["{ah}", "{link}", "{ahp}", "{folder}", "{nodir}",
                                                         "{out}.xyz"])
    + _opt(["plot", "-o", "{out}"], "--replay", ["{missing}", "{latin1}", "{ah}", "{folder}"], FILE)
    + _opt(["plot", "--replay", "{ah}"], "-o", ["{ah}", "{link}"])
    # budget (the params' error values as bounds)
    + _opt(["budget"] + AH + ["--params", "{ahp}"], "--grid", ["1", "0", "-1", "2000001", "100000"] + INTEGERS,
           "grid")
    + _opt(["budget"] + AH + ["--params", "{ahp}"], "--samples", ["-1", "2000001"] + INTEGERS)
    + _opt(["budget"] + AH + ["--params", "{ahp}"], "--seed", ["-1", str(2**32), "nan"])
    + _opt(["budget"] + AH + ["--params", "{ahp}"], "--top", ["-1", "nan"])
    + _opt(["budget"] + AH + ["--params", "{ahp}"], "--over", ["Ap,Ap", "Q"])
    + _opt(["budget"] + AH + ["--params", "{ahp}", "--plot", "{out}"], "--map", ["Ap,Ap", "Ap,Q"])
    + _opt(["budget"] + AH + ["--params", "{ahp}"], "--plot", ["{ah}", "{link}", "{ahp}", "{folder}", "{nodir}",
                                                               "{out}.xyz"])
    + _opt(["budget", "{five}"], "--tolerances", ["{missing}", "{latin1}", "{folder}"], FILE)
    # simulate-calibration
    + _opt(["simulate-calibration", "{five}", "-o", "{out}.yaml"], "--knots", ["1", "0", "4097"] + INTEGERS)
    + _opt(["simulate-calibration", "{five}", "-o", "{out}.yaml"], "--seed", ["-1", str(2**32), "nan"])
    + _opt(["simulate-calibration", "{five}"], "-o", ["{five}", "{folder}", "{nodir}"])
    + _opt(["simulate-calibration", "{five}", "--params", "{ahp}"], "-o", ["{ahp}"])
    + _opt(["simulate-calibration", "{five}", "-o", "{out}.yaml"], "--params", ["{missing}", "{latin1}", "{folder}"],
           FILE)
    # simulate-log
    + _opt(["simulate-log", "{five}", "-o", "{out}.log"], "--rate", ["0", "-1", "2e6"] + NUMBERS)
    + _opt(["simulate-log", "{five}", "-o", "{out}.log"], "--seconds", ["0", "-1", "1e10"] + NUMBERS)
    + [(["simulate-log", "{five}", "-o", "{out}.log", "--rate", "1e6", "--seconds", "5"], "--seconds")]
    + _opt(["simulate-log", "{five}", "-o", "{out}.log"], "--channel", ["", " X", "A" * 64])
    + _opt(["simulate-log", "{five}", "-o", "{out}.log"], "--start-utime", ["-1", str(2**63), "1.5", "nan"])
    + _opt(["simulate-log", "{five}"], "-o", ["{five}", "{folder}", "{nodir}"])
    # report, generate: outputs
    + _opt(["report"] + AH, "-o", ["{ah}", "{link}", "{folder}", "{nodir}"])
    + _opt(["generate"] + AH, "-o", ["{ah}"])
    + _opt(["report"] + AH, "--assume-zero", ["ThetaAs"])
)
# The first input file: missing, not UTF-8, a folder, for every verb that takes one (replay
# hands it to the C++ loader: tests/python/runtime/test_replay_plot.py).
for verb, tail in (("derive", []), ("eval", []), ("generate", ["-o", "{folder}"]), ("testvectors", ["-o", "{out}"]),
                   ("protocol", []), ("plot", ["-o", "{out}"]), ("check", ["{check}"]), ("report", []),
                   ("budget", ["--params", "{ahp}"]), ("simulate-calibration", ["-o", "{out}.yaml"]),
                   ("simulate-log", ["-o", "{out}.log"]), ("identify", ["{ahp}"]),
                   ("simulate-measurements", ["-o", "{out}.csv"]), ("lint", []), ("build", []),
                   # iso230-2 takes a CSV of laser runs first: the same three cases for it
                   ("iso230-2", [])):
    CASES += [([verb, m] + tail, m) for m in ("{missing}", "{latin1}", "{folder}")]
# laser-to-params: the CSV of laser runs after the machine file
CASES += [(["laser-to-params", "{five}", m, "--error", "EXX", "-o", "{out}.yaml"], m)
          for m in ("{missing}", "{latin1}", "{folder}")]


def _id(case) -> str:
    argv, _ = case
    return " ".join(a.replace("{", "").replace("}", "") or "''" for a in argv)[:90]


@pytest.mark.parametrize("argv,word", CASES, ids=[_id(c) for c in CASES])
def test_bad_value_exits_2_in_one_line(ws, capsys, argv, word):
    folder = os.path.dirname(ws["ah"])
    before = _snapshot(folder)
    code, out, err = run(capsys, [a.format(**ws) for a in argv])
    assert code == 2, (code, err)
    assert "Traceback" not in err and err.endswith("\n") and err.count("\n") == 1, err
    assert err.startswith(f"chaincomp {argv[0]}: error: "), err
    assert word.format(**ws) in err, err
    assert _snapshot(folder) == before, "an input was changed or an output written"
    assert out == ""   # nothing half-printed before the refusal


def test_the_last_resort_handler_gives_one_line_and_exit_3(ws, capsys, monkeypatch):
    from chaincomp.cli import derive

    def broken(args):
        raise KeyError("a bug\nover two lines")

    monkeypatch.setattr(derive, "run", broken)
    code, out, err = run(capsys, ["derive", ws["ah"]])
    assert code == 3 and out == ""
    assert err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith("chaincomp derive: internal error: KeyError: ") and "please report" in err
    monkeypatch.setenv("CHAINCOMP_DEBUG", "1")   # developers get the exception itself
    with pytest.raises(KeyError):
        cli.main(["derive", ws["ah"]])


@pytest.mark.parametrize("exc", [MemoryError, RecursionError])
def test_too_large_or_deep_exits_2(ws, capsys, monkeypatch, exc):
    from chaincomp.cli import derive

    def broken(args):
        raise exc()

    monkeypatch.setattr(derive, "run", broken)
    code, _, err = run(capsys, ["derive", ws["ah"]])
    assert code == 2 and err.count("\n") == 1 and "too large or too deeply nested" in err


def _with_acos(ws) -> str:
    """angle_head with a spindle length of G*(1 + acos(e/10)): real at the nominal e = 10,
    not real for e > 10 (acos is defined on [-1, 1] only)."""
    text = open(ws["ah"], encoding="utf-8").read()
    old = "{translate: [0, 0, -G],"
    assert old in text
    path = os.path.join(os.path.dirname(ws["ah"]), "acos.yaml")
    with open(path, "w", encoding="utf-8") as f:
        f.write(text.replace(old, "{translate: [0, 0, -G*(1 + acos(e/10))],"))
    return path


@pytest.mark.parametrize("json_flag", [[], ["--json"]])
def test_eval_refuses_a_non_finite_result_naming_it(ws, capsys, json_flag):
    path = _with_acos(ws)
    code, out, _ = run(capsys, ["eval", path, "--set", "e=9"] + json_flag)   # inside the domain
    assert code == 0
    if json_flag:
        assert all(math.isfinite(v) for v in json.loads(out)["position"])
    code, out, err = run(capsys, ["eval", path, "--set", "e=20"] + json_flag)
    assert code == 2 and err.count("\n") == 1
    assert "position[" in err and "not finite" in err
    # JSON mode: stdout is still JSON, the error's line and exit code
    assert (json.loads(out)["error"] == {"verb": "eval", "kind": "bad input", "exit": 2, "message": err.strip()}
            if json_flag else out == "")


def test_json_output_is_strict_json(ws, capsys):
    """No NaN or Infinity tokens: json.loads with a parse_constant that refuses them."""
    def refuse(token):
        raise AssertionError(f"non-JSON token {token}")

    for argv in (["eval", ws["ah"], "--params", ws["ahp"], "--json"],
                 ["protocol", ws["ah"], "--format", "json"],
                 ["budget", ws["ah"], "--params", ws["ahp"], "--grid", "3", "--samples", "100", "--format", "json"]):
        code, out, _ = run(capsys, argv)
        assert code == 0
        json.loads(out, parse_constant=refuse)


@pytest.mark.slow
def test_simulate_calibration_at_the_knot_limit_loads_back(ws, capsys):
    from chaincomp.model.machine import load_machine
    from chaincomp.model.params import load_params
    from chaincomp.model.varying import MAX_TABLE_KNOTS, Table

    out = ws["out"] + ".yaml"
    code, _, err = run(capsys, ["simulate-calibration", ws["five"], "-o", out, "--knots", str(MAX_TABLE_KNOTS),
                                "--seed", str(2**32 - 1)])
    assert code == 0, err
    values = load_params(out, load_machine(ws["five"]))
    tables = [v for v in values.values() if isinstance(v, Table)]
    assert tables and all(len(t.x) == MAX_TABLE_KNOTS for t in tables)
    assert not [f for f in os.listdir(os.path.dirname(out)) if f.endswith(".tmp")]
    # the C++ loader too: replay a few commands with it (the compiled compensator reads the tables)
    log, csv_path = ws["out"] + ".lcmlog", ws["out"] + ".csv"
    assert run(capsys, ["simulate-log", ws["five"], "-o", log, "--seconds", "0.01"])[0] == 0
    proc = subprocess.run([sys.executable, "-m", "chaincomp.cli.main", "replay", ws["five"], log,
                           "--params", out, "--csv", csv_path], capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    with open(csv_path, encoding="utf-8") as f:
        assert sum(1 for line in f if ",ok," in line) == 10


def test_protocol_bounds_its_set_ups(ws, capsys):
    from chaincomp.measure.protocol import MAX_SETUPS

    # angle_head: Ap and Cp over the same values, both within limits: n^2 set-ups
    n = math.isqrt(MAX_SETUPS) + 1
    angles = ",".join(str(a) for a in range(n))
    code, _, err = run(capsys, ["protocol", ws["ah"], "--angles", angles])
    assert code == 2 and f"{n * n} set-ups, at most {MAX_SETUPS}" in err


@pytest.mark.slow
def test_a_subprocess_sees_no_traceback_either(ws):
    """The entry point as a user runs it: argparse's error and a verb's error, one line each."""
    for argv in (["protocol", ws["ah"], "--angles", "nan,inf"], ["simulate-log", ws["five"], "-o", ws["out"],
                                                                 "--rate", "nan"]):
        proc = subprocess.run([sys.executable, "-m", "chaincomp.cli.main", *argv], capture_output=True, text=True,
                              cwd=ROOT)
        assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr, \
            proc.stderr


@pytest.mark.slow
def test_number_parsers_take_every_float_and_refuse_everything_else_cleanly():
    """parse_number reads back any finite float's repr exactly, and on any other text either
    returns a finite number or raises ValueError: never another exception."""
    import argparse

    from hypothesis import given, settings
    from hypothesis import strategies as st

    from chaincomp.cli.common import integer, parse_number

    @settings(max_examples=300, deadline=None)
    @given(st.floats(allow_nan=False, allow_infinity=False))
    def exact(x):
        assert parse_number(repr(x)) == x and parse_number(f"{x:.17e}") == x

    @settings(max_examples=300, deadline=None)
    @given(st.text(max_size=40))
    def clean(text):
        try:
            assert math.isfinite(parse_number(text))
        except ValueError:
            pass
        try:
            assert -5 <= integer(-5, 5)(text) <= 5
        except argparse.ArgumentTypeError:
            pass

    exact()
    clean()
    assert parse_number(" -1.5e3 ") == -1500.0 and integer(0, 9)("+7") == 7


@pytest.mark.slow
def test_replay_checks_machine_and_outputs_before_the_binary(tmp_path):
    """replay: the machine file validated as every verb validates it, and an output that is an
    input (or -o and --csv the same file) refused before the C++ binary runs."""
    machine = os.path.join(ROOT, "configs", "machines", "angle_head.yaml")
    params = os.path.join(ROOT, "configs", "params", "angle_head-fig3.yaml")
    log = tmp_path / "a.lcmlog"
    log.write_bytes(b"not a log, never read")
    bad = tmp_path / "bad.yaml"
    bad.write_bytes(b"name: caf\xe9\n")

    def replay(machine, *args):
        return subprocess.run([sys.executable, "-m", "chaincomp.cli.main", "replay", str(machine), str(log),
                               *map(str, args)],
                              capture_output=True, text=True, cwd=ROOT, timeout=120)
    proc = replay(bad, "--params", params)
    assert proc.returncode == 2 and f"{bad}:1: not UTF-8 text (byte 0xe9)" in proc.stderr, proc.stderr
    proc = replay(machine, "--params", params, "-o", log)
    assert proc.returncode == 2 and "is also an input" in proc.stderr, proc.stderr
    proc = replay(machine, "--params", params, "-o", tmp_path / "o", "--csv", tmp_path / "o")
    assert proc.returncode == 2 and "is also the -o output" in proc.stderr, proc.stderr
    assert log.read_bytes() == b"not a log, never read"
