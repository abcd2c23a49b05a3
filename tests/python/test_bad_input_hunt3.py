"""The third bad-input hunt: faults found by hand in verbs whose authors have finished, each with
the message and exit code the contract asks for written here (exit 2 and one line naming the
option, or the file, line and field; never exit 3, never a silent wrong value or a silent
success)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from chaincomp.cli.main import main
from conftest import machine_path

VMC = machine_path("vmc_xyz")


def _run(capsys, *argv) -> tuple[int, str, str]:
    capsys.readouterr()
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _refused(capsys, *argv, match: str) -> str:
    code, out, err = _run(capsys, *argv)
    assert code == 2, err
    assert match in err, err
    assert "Traceback" not in err and "internal error" not in err
    return err


@pytest.fixture(scope="module")
def measurements(tmp_path_factory) -> str:
    """Tool points of vmc_xyz at 30 random set-ups, no errors, 1 um noise (input data only)."""
    path = tmp_path_factory.mktemp("meas") / "meas.csv"
    assert main(["simulate-measurements", VMC, "--setups", "random:30", "--noise", "1um", "-o", str(path)]) == 0
    return str(path)


# ----------------------------------------------------------------------------- identify



@pytest.mark.parametrize("weight", ["1e13", "1e200", "1e306"])
def test_identify_refuses_a_smoothing_weight_beyond_1e12(capsys, measurements, weight):
    """At 1e200 the fit printed (0.0 ± 1.0)e-100 µm, at 1e306 'nothing to identify'."""
    _refused(capsys, "identify", VMC, measurements, "--minimal", "--vary", "EXX=table:-400,0,400",
             "--sigma", "1um", "--smooth", weight,
             match=f"argument --smooth: must be at least 0 and at most 1e+12, got '{weight}'")


def test_identify_at_the_smoothing_bound_still_fits_a_straight_table(tmp_path):
    """EXX a tent 0, 3, 0 um over X's knots -400, 0, 400 mm, every other error zero and held so:
    without smoothing the fit finds the tent (within 4 standard uncertainties); at the bound,
    1e12, the second difference is nil (a straight table) and every number finite."""
    from chaincomp.measure.identify import Vary, identify, read_table
    from chaincomp.model.machine import load_machine
    p, meas = tmp_path / "p.yaml", tmp_path / "meas.csv"
    p.write_text("machine: vmc_xyz\nvalues:\n  EXX:\n    axis: X\n    units: [mm, um]\n    interpolation: linear\n"
                 "    outside: hold\n    table:\n      - [-400, 0]\n      - [0, 3]\n      - [400, 0]\n")
    assert main(["simulate-measurements", VMC, "--params", str(p), "--setups", "random:40", "--noise", "0.1um",
                 "--seed", "5", "-o", str(meas)]) == 0
    m = load_machine(VMC)
    others = tuple(s.name for s in m.errors if s.name != "EXX")
    knots = ("EXX@X=-400", "EXX@X=0", "EXX@X=400")
    vary = [Vary("EXX", "X", "table", (-400.0, 0.0, 400.0))]
    fit = identify(m, read_table(str(meas), m), others, 1e-4, vary=vary)
    v, u = (np.array([d[k] * 1e3 for k in knots]) for d in (fit.estimates, fit.uncertainties))   # um
    assert np.all(np.abs(v - [0, 3, 0]) < 4 * u), (v, u)
    fit = identify(m, read_table(str(meas), m), others, 1e-4, vary=vary, smooth=1e12)
    v = np.array([fit.estimates[k] * 1e3 for k in knots])
    assert fit.converged and np.all(np.isfinite(v)) and abs(v[0] - 2 * v[1] + v[2]) < 1e-5, v


def test_identify_api_refuses_a_smoothing_weight_beyond_1e12(measurements):
    from chaincomp.errors import ChaincompError
    from chaincomp.measure.identify import identify, read_table
    from chaincomp.model.machine import load_machine
    m = load_machine(VMC)
    with pytest.raises(ChaincompError, match="--smooth: must be at least 0 and at most 1e"):
        identify(m, read_table(measurements, m), sigma=1e-3, smooth=1e13)


@pytest.mark.parametrize("option", ["--prefer", "--assume-zero", "--vary", "--sigma"])
@pytest.mark.parametrize("value", ["", " "])
def test_identify_refuses_an_empty_option_value(capsys, measurements, option, value):
    """--prefer '' and --assume-zero '' were ignored (exit 0, the fit as without them)."""
    _refused(capsys, "identify", VMC, measurements, "--minimal", option, value,
             match=f"chaincomp identify: error: {option}: an empty value (leave the option out for its default)")


# ----------------------------------------------------------------------------- empty -o and --params

@pytest.mark.parametrize("argv", [
    ["protocol", machine_path("panda"), "--poses", "30", "-o"],        # designed 30 poses, wrote nothing
    ["identify", VMC, "MEAS", "-o"],
    ["simulate-measurements", VMC, "-o"],
    ["testvectors", VMC, "-o"],
    ["report", VMC, "-o"],
    ["budget", VMC, "--plot"],
])
@pytest.mark.parametrize("value", ["", "  "])
def test_an_empty_output_is_refused_before_any_work(capsys, monkeypatch, tmp_path, measurements, argv, value):
    import chaincomp.cli.protocol as protocol

    def no_design(*args, **kwargs):
        raise AssertionError("designed the poses before refusing -o")
    monkeypatch.setattr(protocol, "design_poses", no_design)
    monkeypatch.chdir(tmp_path)
    argv = [measurements if a == "MEAS" else a for a in argv]
    _refused(capsys, *argv, value, match=f"{argv[-1]}: an empty value (expected a file name)")
    assert list(tmp_path.iterdir()) == []


def test_build_refuses_an_empty_output_folder_before_compiling(capsys, monkeypatch, tmp_path):
    """build --linuxcnc -o '' compiled (minutes) and exited 0 without saying where it put the library."""
    import chaincomp.cli.build as verb

    def no_compile(*args, **kwargs):
        raise AssertionError("compiled before refusing the option")
    monkeypatch.setattr(verb, "build", no_compile)
    monkeypatch.setattr(verb, "build_linuxcnc", no_compile)
    _refused(capsys, "build", VMC, "--linuxcnc", "-o", "", match="-o: an empty value (expected a folder)")
    _refused(capsys, "build", VMC, "-o", " ", match="-o: an empty value (expected a folder)")
    _refused(capsys, "build", VMC, "--linuxcnc", "--params", "",
             match="--params: an empty value (leave the option out for every error zero)")


@pytest.mark.parametrize("argv", [["budget", VMC]])
def test_an_empty_params_value_is_refused(capsys, argv):
    """--params '' ran with every error zero (common.values_for read it as no params file)."""
    _refused(capsys, *argv, "--params", "",
             match="--params: an empty value (leave the option out for no error values)")


# ----------------------------------------------------------------------------- figures on a full disk

def _iso_runs(tmp_path) -> str:
    path = tmp_path / "runs.csv"
    rows = [f"{t},{j},{d},{0.1 * j + (0.5 if d == 'up' else -0.5)}"
            for j in (1, 2, 3) for d in ("up", "down") for t in (0, 100, 200)]
    path.write_text("target [mm],run,direction,deviation [um]\n" + "\n".join(rows) + "\n")
    return str(path)


@pytest.mark.parametrize("verb", ["budget", "iso230-2"])
def test_a_figure_on_a_full_disk_is_an_error_naming_the_file(capsys, monkeypatch, tmp_path, verb):
    """fig.savefig straight onto /dev/full raised OSError: exit 3. /dev/full takes the open and
    refuses every write (ENOSPC) to anyone; the up-front check_image (which as root passes it
    anyway) is skipped so that the write itself fails."""
    import importlib
    module = importlib.import_module(f"chaincomp.cli.{verb.replace('-', '_')}")
    monkeypatch.setattr(module, "check_image", lambda *args, **kwargs: None)
    argv = [verb, VMC, "--set", "EXX=1", "--grid", "2"] if verb == "budget" else [verb, _iso_runs(tmp_path)]
    _refused(capsys, *argv, "--plot", "/dev/full",
             match=f"chaincomp {verb}: error: /dev/full: cannot write: No space left on device")


# ----------------------------------------------------------------------------- import-urdf

GANTRY = """<?xml version="1.0"?>
<robot name="gantry">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="l3"/><link name="tool"/>
  <joint name="x" type="prismatic">
    <parent link="base"/><child link="l1"/><origin xyz="0.1 0 0"/><axis xyz="1 0 0"/>
    <limit lower="-0.5" upper="0.5" effort="1" velocity="1"/>
  </joint>
  <joint name="y" type="prismatic">
    <parent link="l1"/><child link="l2"/><origin xyz="0 0.2 0"/><axis xyz="0 1 0"/>
    <limit lower="-0.5" upper="0.5" effort="1" velocity="1"/>
  </joint>
  <joint name="z" type="prismatic">
    <parent link="l2"/><child link="l3"/><origin xyz="0 0 0.3"/><axis xyz="0 0 1"/>
    <limit lower="-0.5" upper="0.5" effort="1" velocity="1"/>
  </joint>
  <joint name="kx" type="revolute">
    <parent link="l3"/><child link="tool"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
</robot>
"""


def test_import_urdf_renames_joints_named_like_a_measured_coordinate(capsys, tmp_path):
    """Joints x, y, z became axes x, y, z, which identify and simulate-measurements then refuse
    (a column x would be both the axis and the measured coordinate)."""
    import json

    from chaincomp.measure import identify

    from chaincomp.model import urdf
    assert set(urdf.MEASURED_NAMES) == set(identify.COLUMNS)
    src, m = tmp_path / "gantry.urdf", tmp_path / "gantry.yaml"
    src.write_text(GANTRY)
    code, _, err = _run(capsys, "import-urdf", src, "--base", "base", "--tip", "tool", "--errors", "joint-offsets",
                        "--tool-point", "0,0,50", "-o", m)
    assert code == 0, err
    text = m.read_text()
    assert ("# kx, ky, kz, the measured coordinates' names): x -> x_, y -> y_, z -> z_, kx -> kx_\n"
            in text), text
    # the tool point by hand: the origins and the slides add, in metres -> mm (the tip's 50 mm
    # along z, which the rotation kx_ leaves where it is)
    code, out, err = _run(capsys, "eval", m, "--set", "x_=10", "--set", "y_=-20", "--set", "z_=30",
                          "--set", "kx_=40", "--json")
    assert code == 0, err
    assert json.loads(out)["position"] == pytest.approx([110.0, 180.0, 380.0], abs=1e-9)
    meas = tmp_path / "meas.csv"
    code, _, err = _run(capsys, "simulate-measurements", m, "--setups", "random:20", "-o", meas)
    assert code == 0, err
    code, out, err = _run(capsys, "identify", m, meas, "--assume-zero", "kx__zero", "--sigma", "1um")
    assert code == 0, err
    assert "x__zero" in out


# ----------------------------------------------------------------------------- integer options

def test_an_integer_option_with_a_control_character_is_not_an_internal_error(capsys):
    """str.strip() takes '\\x1f' (a unit separator) off, int() does not: '--grid 3\\x1f' passed
    the digits check and int() raised ValueError (exit 3). test_cli_options' property test found it."""
    from chaincomp.cli.common import integer
    assert integer(1, 10)("3\x1f") == 3 and integer(1, 10)(" 4\n") == 4
    code, _, err = _run(capsys, "protocol", VMC, "--poses", "1\x1f0x")
    assert code == 2 and "argument --poses: expected an integer, got '1\\x1f0x'" in err, err


def test_simulate_measurements_refuses_an_empty_params(tmp_path):
    # '' (an unset shell variable) is a typo, not a request for every error at zero
    proc = subprocess.run([sys.executable, "-m", "chaincomp.cli.main", "simulate-measurements",
                           machine_path("vmc_xyz"), "--params", "", "-o", str(tmp_path / "m.csv")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "--params: an empty value" in proc.stderr, proc.stderr
    assert not (tmp_path / "m.csv").exists()


# ----------------------------------------------------------------------------- YAML 1.1 exponents

@pytest.mark.parametrize("written,hint", [
    ("1.0e300", "write 1.0e+300"), ("1e15", "write 1.0e+15"), ("1e+3", "write 1.0e+3"),
    (".5e3", "write .5e+3"), ("-2E5", "write -2.0e+5"),
])
def test_a_yaml11_text_exponent_says_how_to_write_the_number(capsys, tmp_path, written, hint):
    """PyYAML (YAML 1.1) reads an exponent number without a dot and a sign as text: the message
    said 'expected a number, got str ...' and no more. Each suggested spelling is read back here
    by PyYAML as a number."""
    import yaml
    suggested = hint.split()[-1]
    assert isinstance(yaml.safe_load(f"v: {suggested}")["v"], float)
    assert yaml.safe_load(f"v: {written}")["v"] == written
    p = tmp_path / "p.yaml"
    p.write_text(f"machine: vmc_xyz\nvalues:\n  EXX: {{axis: X, units: [mm, um], polynomial: [{written}, 2]}}\n")
    _refused(capsys, "eval", VMC, "--params", p,
             match=f"p.yaml:3: values.EXX.polynomial[0]: expected a number, got str '{written}' "
                   f"(YAML reads {written} as text: {hint})")


def test_a_quoted_number_gets_no_spelling_hint(capsys, tmp_path):
    p = tmp_path / "p.yaml"
    p.write_text("machine: vmc_xyz\nvalues:\n  EXX: {axis: X, units: [mm, um], polynomial: ['1.0e+3', 2]}\n")
    err = _refused(capsys, "eval", VMC, "--params", p, match="expected a number, got str '1.0e+3'")
    assert "YAML reads" not in err
