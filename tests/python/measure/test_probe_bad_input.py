"""Bad input to chaincomp probe: one line `chaincomp probe ACTION: error: FILE:LINE: FIELD: message`,
exit 2, nothing written (docs/reference/errors.md)."""

import pytest

from helpers import cli, machine_path

NUTATING = machine_path("nutating_bc45")
SPHERE = ["--sphere", "50,30,80", "--radius", "12.5", "--stylus", "2"]
LINE = "43.107207 46.123015 -208.266547 0.000000 -3.000000 0.000000 0.000000 0.000000 0.000000\n"


def refused(tmp_path, *args, code=2):
    out = tmp_path / "out.yaml"
    r = cli(*args, "-o", str(out), check=False) if args[1] != "plan" else cli(*args, "--csv", str(out), check=False)
    assert r.returncode == code, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and r.stderr.startswith(f"chaincomp probe {args[1]}: error: ")
    assert not out.exists()
    return r.stderr


@pytest.mark.parametrize("text, message", [
    (LINE + "1 2 3 4 5 6 7 8\n", "log.txt:2: expected the nine numbers X Y Z A B C U V W"),
    (LINE + LINE.replace("43.107207", "nan"), "log.txt:2: "),
    ("", "no touches: the probe log is empty"),
])
def test_a_bad_probe_log_is_named_at_its_line(tmp_path, text, message):
    (tmp_path / "log.txt").write_text(text)
    assert message in refused(tmp_path, "probe", "fit", NUTATING, str(tmp_path / "log.txt"), *SPHERE)


def test_a_log_that_is_not_the_plans(tmp_path):
    plan = tmp_path / "plan.csv"
    cli("probe", "plan", NUTATING, *SPHERE, "--csv", str(plan))
    (tmp_path / "log.txt").write_text(LINE * 3)
    err = refused(tmp_path, "probe", "fit", NUTATING, str(tmp_path / "log.txt"), "--plan", str(plan), *SPHERE)
    assert "3 touches, but the plan has 96" in err


def test_too_few_touches_at_a_position(tmp_path):
    (tmp_path / "t.csv").write_text("X,Y,Z,B,C\n1,2,3,0,0\n2,2,3,0,0\n1,3,3,0,0\n")
    err = refused(tmp_path, "probe", "fit", NUTATING, str(tmp_path / "t.csv"), *SPHERE)
    assert "t.csv:2: 3 touches at this position" in err


def test_a_csv_with_an_unknown_column(tmp_path):
    (tmp_path / "t.csv").write_text("X,Y,Z,B,C,Q\n1,2,3,0,0,1\n")
    assert "t.csv:1: header: unknown column 'Q'" in refused(tmp_path, "probe", "fit", NUTATING,
                                                             str(tmp_path / "t.csv"), *SPHERE)


@pytest.mark.parametrize("args, message", [
    (["--positions", "B=0"], "gives no value for C"),
    (["--positions", "B=0,C=0;B=400,C=0"], "B = 400 deg is outside its limits"),
    (["--positions", "A=0,C=0"], "expected AXIS=VALUE for the rotary axes B, C"),
    (["--sphere", "1,2"], "--sphere: expected X,Y,Z"),
    (["--sphere", "5000,0,0"], "0 rotary positions within the limits"),
    (["--sphere", "500,0,0", "--positions", "B=0,C=0;B=90,C=0"],
     "--positions: position 1 (B = 0, C = 0) would take X to"),
])
def test_plan_options(tmp_path, args, message):
    sphere = [a for a in SPHERE if a not in ("--sphere", "50,30,80")] if "--sphere" in args else SPHERE
    assert message in refused(tmp_path, "probe", "plan", NUTATING, *sphere, *args)


def test_a_machine_without_rotary_axes(tmp_path):
    err = refused(tmp_path, "probe", "plan", machine_path("vmc_xyz"), *SPHERE)
    assert "sphere probing needs three linear axes" in err and "0 rotary" in err


def test_hold_and_assume_zero_of_one_error(tmp_path):
    (tmp_path / "h.yaml").write_text("machine: nutating_bc45\nvalues:\n  EX0C: 3 um\n")
    err = refused(tmp_path, "probe", "plan", NUTATING, *SPHERE, "--hold", str(tmp_path / "h.yaml"),
                  "--assume-zero", "EX0C")
    assert "EX0C is also assumed zero" in err


def test_hold_of_a_constant(tmp_path):
    (tmp_path / "h.yaml").write_text("machine: nutating_bc45\nvalues:\n  L: 90 mm\n")
    err = refused(tmp_path, "probe", "plan", NUTATING, *SPHERE, "--hold", str(tmp_path / "h.yaml"))
    assert "L is a constant of nutating_bc45, not an error" in err
