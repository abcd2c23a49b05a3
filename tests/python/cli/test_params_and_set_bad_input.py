"""--params and --set across the verbs: an empty value, one symbol set twice, two symbols in one
item, values beyond the limits the machine file gives (a warning, the value used as given)."""

from __future__ import annotations

import json

import pytest

from helpers import DH, M4, VMC, cli, edited, refused, refused_one_line, write_file


@pytest.mark.parametrize("verb,options", [
    ("eval", []),
    ("plot", ["-o", "x.png"]),
    ("ballbar", ["--plane", "XY", "--radius", "10"]),
])
def test_an_empty_params_value_is_refused(capsys, tmp_path, monkeypatch, verb, options):
    """--params '' ran with every error zero: eval printed the nominal pose alone, exit 0."""
    monkeypatch.chdir(tmp_path)
    refused(capsys, verb, VMC, "--params", "", *options, match="--params: an empty value")

# A four-axis machine written the way a user would: X, Y, Z slides and a B table, one error block
# after each, a tool length L.

# A three-joint arm in standard DH with a Hayati beta.


# ----------------------------------------------------------------------------- --set

@pytest.mark.parametrize("verb, extra", [("eval", ()), ("protocol", ("--poses", "30"))])
def test_set_of_one_symbol_twice_is_refused(tmp_path, verb, extra):
    """Before, the second silently won (eval printed X = 20)."""
    path = write_file(tmp_path, "arm.yaml", DH)
    refused_one_line(verb, path, *extra, "--set", "q1=10", "--set", "q1=20 deg",
             match=f"chaincomp {verb}: error: --set q1 given twice ('10', then '20 deg'): set each symbol once")


def test_set_of_two_symbols_in_one_item_says_how_to_write_it(tmp_path):
    """Before: --set X: unknown unit ',Y=20' (expected one of: mm, m, ...)."""
    path = write_file(tmp_path, "m.yaml", M4)
    refused_one_line("eval", path, "--set", "X=10,Y=20",
             match="--set X: '10,Y=20' sets more than one symbol: give one --set per symbol (--set X=10 --set Y=20)")
    out = cli("eval", path, "--set", "X=10", "--set", "Y=3mm", "--json").stdout
    assert json.loads(out)["axes"] == {"X": 10.0, "Y": 3.0, "Z": 0.0, "B": 0.0}


def test_a_constant_or_error_beyond_the_limits_the_machine_file_gives_it_warns(tmp_path):
    """The loader checks a constant's nominal against its limits, but a --params or --set value
    beyond them went without a word (axes warn)."""
    text = edited(M4, "{name: L, role: constant, unit: mm, nominal: 120}",
                   "{name: L, role: constant, unit: mm, nominal: 120, limits: [100, 200]}")
    text = edited(text, "{name: EXX, role: error, unit: um}", "{name: EXX, role: error, unit: um, limits: [-5, 5]}")
    path = write_file(tmp_path, "m.yaml", text)
    params = write_file(tmp_path, "p.yaml", "machine: m4\nvalues:\n  L: 500 mm\n  EXX: 50 um\n")
    proc = cli("eval", path, "--params", params, "--json")
    assert f"chaincomp: warning: constant L = 500 mm is outside its limits [100, 200] ({path}:11)" in proc.stderr
    assert f"chaincomp: warning: error EXX = 50 um is outside its limits [-5, 5] ({path}:12)" in proc.stderr
    # the values are used as given: the tool 500 mm below, moved 50 um in x
    out = json.loads(proc.stdout)
    assert out["position"] == pytest.approx([0, 0, -500])
    assert out["error"]["exact"] == pytest.approx([0.05, 0, 0])
    assert "warning" not in cli("eval", path, "--set", "L=150", "--set", "EXX=1").stderr
