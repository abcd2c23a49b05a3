"""chaincomp iso230-2 against ISO 230-2:2014's definitions, implemented again here in plain
Python (statistics.mean / statistics.stdev, one target at a time) on runs generated with a
known systematic deviation, reversal and noise."""

import json
import math
import random
import statistics

import pytest

from chaincomp.cli.main import main
from helpers import RUNS


def systematic(p):          # µm: a scale error of 12 µm/m and a wave, as a ball screw gives
    return 0.012 * p + 1.5 * math.sin(p / 70.0)


def reversal(p):            # µm: backlash that grows along the travel
    return 2.0 + 0.002 * p


def make_runs(targets, n, sigma, seed, drop=None, backlash=1.0, sigma_down=None):
    """{(target, direction, run): deviation µm}: up = systematic + B/2 + noise, down = ... - B/2."""
    rnd = random.Random(seed)
    out = {}
    for j in range(1, n + 1):
        for d, half, sd in (("up", 0.5, sigma), ("down", -0.5, sigma if sigma_down is None else sigma_down)):
            for t in targets:
                out[(t, d, j)] = systematic(t) + half * backlash * reversal(t) + rnd.gauss(0, sd)
    if drop:
        del out[drop]
    return out


def write_csv(path, readings, header="target [mm],run,direction,deviation [um]", seed=0, fmt=None):
    rows = list(readings.items())
    random.Random(seed).shuffle(rows)      # any order: the evaluator groups the readings
    fmt = fmt or (lambda t, d, j, v: f"{t!r},{j},{d},{v!r}")
    with open(path, "w") as f:
        f.write("# synthetic runs for the tests\n\n" + header + "\n")
        for (t, d, j), v in rows:
            f.write(fmt(t, d, j, v) + "\n")


def reference(readings):
    """ISO 230-2:2014 §3 and §7, straight from the definitions."""
    targets = sorted({t for t, _, _ in readings})
    per = []
    for t in targets:
        up = [v for (tt, d, _), v in readings.items() if tt == t and d == "up"]
        dn = [v for (tt, d, _), v in readings.items() if tt == t and d == "down"]
        xu, xd = statistics.mean(up), statistics.mean(dn)
        su, sd = statistics.stdev(up), statistics.stdev(dn)   # 1/(n-1)
        b = xu - xd
        per.append(dict(target=t, mean_up=xu, mean_down=xd, mean=(xu + xd) / 2, reversal=b, s_up=su, s_down=sd,
                        R_up=4 * su, R_down=4 * sd, R_i=max(2 * su + 2 * sd + abs(b), 4 * su, 4 * sd)))
    col = lambda k: [q[k] for q in per]  # noqa: E731
    hi_u = [q["mean_up"] + 2 * q["s_up"] for q in per]
    lo_u = [q["mean_up"] - 2 * q["s_up"] for q in per]
    hi_d = [q["mean_down"] + 2 * q["s_down"] for q in per]
    lo_d = [q["mean_down"] - 2 * q["s_down"] for q in per]
    axis = dict(
        B=max(abs(b) for b in col("reversal")), B_mean=sum(col("reversal")) / len(per),
        E_up=max(col("mean_up")) - min(col("mean_up")), E_down=max(col("mean_down")) - min(col("mean_down")),
        E=max(col("mean_up") + col("mean_down")) - min(col("mean_up") + col("mean_down")),
        M=max(col("mean")) - min(col("mean")),
        R_up=max(col("R_up")), R_down=max(col("R_down")), R=max(col("R_i")),
        A_up=max(hi_u) - min(lo_u), A_down=max(hi_d) - min(lo_d), A=max(hi_u + hi_d) - min(lo_u + lo_d))
    return per, axis


def evaluate(capsys, path, *options):
    code = main(["iso230-2", str(path), "--format", "json", *options])
    out, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(out)


def refused(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


UNEQUAL = [0.0, 37.5, 81.0, 150.25, 202.0, 260.0, 333.3, 401.0, 455.5, 500.0]


@pytest.mark.parametrize("n,backlash,sigma_down", [(2, 1, None), (3, 1, None), (5, 1, None), (12, 1, None),
                                                   (5, 0, 1.5)])   # R_i = R_i↓ at most targets
def test_figures_match_the_standards_definitions(tmp_path, capsys, n, backlash, sigma_down):
    readings = make_runs(UNEQUAL, n, sigma=0.3, seed=n, backlash=backlash, sigma_down=sigma_down)
    write_csv(tmp_path / "runs.csv", readings, seed=n)
    doc = evaluate(capsys, tmp_path / "runs.csv")
    per, axis = reference(readings)
    assert doc["runs"] == n and doc["targets"] == len(UNEQUAL)
    assert doc["units"] == {"position": "mm", "deviation": "um"}
    assert [p["target"] for p in doc["positions"]] == UNEQUAL
    for got, want in zip(doc["positions"], per):
        for k, v in want.items():
            assert got[k] == pytest.approx(v, abs=1e-9), (got["target"], k)
    assert set(doc["axis"]) == set(axis)
    for k, v in axis.items():
        assert doc["axis"][k] == pytest.approx(v, abs=1e-9), k


def test_known_systematic_error_reversal_and_noise_come_back(tmp_path, capsys):
    """With many runs the estimates approach the generating model: x̄↑ = f + B/2, B_i = B, s = σ."""
    n, sigma = 400, 0.25
    targets = [0.0, 100.0, 200.0, 300.0, 400.0]
    write_csv(tmp_path / "runs.csv", make_runs(targets, n, sigma, seed=7))
    doc = evaluate(capsys, tmp_path / "runs.csv")
    tol = 4 * sigma / math.sqrt(n)
    for p in doc["positions"]:
        t = p["target"]
        assert p["mean_up"] == pytest.approx(systematic(t) + reversal(t) / 2, abs=tol)
        assert p["mean_down"] == pytest.approx(systematic(t) - reversal(t) / 2, abs=tol)
        assert p["mean"] == pytest.approx(systematic(t), abs=tol)
        assert p["reversal"] == pytest.approx(reversal(t), abs=2 * tol)
        for s in (p["s_up"], p["s_down"]):   # sd of s is about σ / sqrt(2(n-1))
            assert s == pytest.approx(sigma, abs=4 * sigma / math.sqrt(2 * (n - 1)))
    assert doc["axis"]["B"] == pytest.approx(reversal(400.0), abs=2 * tol)
    assert doc["axis"]["M"] == pytest.approx(max(map(systematic, targets)) - min(map(systematic, targets)),
                                             abs=2 * tol)


@pytest.mark.parametrize("seed", range(8))
def test_textbook_properties(tmp_path, capsys, seed):
    rnd = random.Random(seed)
    targets = sorted(rnd.sample(range(0, 1000, 5), 6))
    write_csv(tmp_path / "runs.csv", make_runs([float(t) for t in targets], rnd.randint(2, 8),
                                               sigma=rnd.uniform(0.05, 2.0), seed=seed))
    doc = evaluate(capsys, tmp_path / "runs.csv")
    a = doc["axis"]
    assert a["R"] >= max(a["R_up"], a["R_down"])
    assert a["A"] >= a["E"] >= max(a["E_up"], a["E_down"])
    assert a["A_up"] >= a["E_up"] and a["A_down"] >= a["E_down"]
    assert a["E"] >= a["M"]
    assert a["A"] >= max(a["A_up"], a["A_down"])
    assert a["B"] >= abs(a["B_mean"])
    for p in doc["positions"]:
        assert p["R_i"] >= max(p["R_up"], p["R_down"]) and p["R_i"] >= abs(p["reversal"])


def test_other_programs_export_through_columns_and_actual_positions(tmp_path, capsys):
    """A semicolon export with its own names, measured positions in mm, runs numbered; the same
    figures as the deviations in µm."""
    readings = make_runs(UNEQUAL, 5, 0.3, seed=3)
    write_csv(tmp_path / "dev.csv", readings)
    write_csv(tmp_path / "export.csv", readings, header="Point;Target Position (mm);Run No;Dir;Measured (mm)",
              fmt=lambda t, d, j, v: f"{UNEQUAL.index(t) + 1};{t!r};{j};{'+' if d == 'up' else '-'};"
                                     f"{t + v / 1000.0!r}")
    want = evaluate(capsys, tmp_path / "dev.csv")
    got = evaluate(capsys, tmp_path / "export.csv", "--columns",
                   "target=Target Position,actual=Measured,run=Run No,direction=Dir")
    for g, w in zip(got["positions"], want["positions"]):
        for k in w:
            assert g[k] == pytest.approx(w[k], abs=1e-6), k   # actual - target loses digits below 1e-9 mm
    # an export with both a deviation and an actual column: the one mapped is used
    write_csv(tmp_path / "both.csv", readings, header="target [mm],run,direction,deviation [um],Error [um]",
              fmt=lambda t, d, j, v: f"{t!r},{j},{d},999,{v!r}")
    got = evaluate(capsys, tmp_path / "both.csv", "--columns", "deviation=Error")
    assert got["positions"] == want["positions"]


def test_units_from_the_option_and_angles(tmp_path, capsys):
    readings = make_runs([0.0, 90.0, 180.0, 270.0], 3, 0.5, seed=1)
    write_csv(tmp_path / "mm.csv", {k: v / 1000 for k, v in readings.items()}, header="target,run,direction,"
                                                                                     "deviation")
    um = evaluate(capsys, tmp_path / "mm.csv", "--column-units", "mm,mm")
    assert um["units"]["deviation"] == "um"
    per, _ = reference(readings)
    assert [p["mean_up"] for p in um["positions"]] == pytest.approx([q["mean_up"] for q in per], abs=1e-9)
    write_csv(tmp_path / "deg.csv", readings, header="target [deg],run,direction,deviation [arcsec]")
    ang = evaluate(capsys, tmp_path / "deg.csv")
    assert ang["units"] == {"position": "deg", "deviation": "arcsec"}


def test_text_report_and_plot(tmp_path, capsys):
    write_csv(tmp_path / "runs.csv", make_runs(UNEQUAL, 5, 0.3, seed=1))
    assert main(["iso230-2", str(tmp_path / "runs.csv"), "--plot", str(tmp_path / "iso.png")]) == 0
    out = capsys.readouterr().out
    assert "R   repeatability, bidirectional, max R_i" in out and "A   accuracy, bidirectional" in out
    with open(tmp_path / "iso.png", "rb") as f:
        assert f.read(8) == b"\x89PNG\r\n\x1a\n"
    line = refused(capsys, "iso230-2", str(tmp_path / "runs.csv"), "--plot", str(tmp_path / "iso.xyz"))
    assert line.startswith("chaincomp iso230-2: error: --plot ") and "cannot write .xyz" in line


def _lines(path):
    with open(path) as f:
        return f.read().splitlines()


def test_a_missing_reading_is_refused_naming_the_target(tmp_path, capsys):
    readings = make_runs(UNEQUAL, 5, 0.3, seed=2, drop=(150.25, "down", 4))
    path = tmp_path / "runs.csv"
    write_csv(path, readings)
    first = next(i for i, t in enumerate(_lines(path), 1) if t.startswith("150.25,"))
    line = refused(capsys, "iso230-2", str(path))
    assert line == (f"chaincomp iso230-2: error: {path}:{first}: target: target 150.25 has no reading for run 4 "
                    "down (every target needs runs 1, 2, 3, 4, 5 in both directions)")


@pytest.mark.parametrize("row,field,message", [
    ("10,1,up,abc", "deviation", "expected a number, got 'abc'"),
    ("10,1,up,nan", "deviation", "expected a finite number, got 'nan'"),
    ("1e999,1,up,0.5", "target", "expected a finite number"),
    ("10,0,up,0.5", "run", "expected a run number"),
    ("10,1.5,up,0.5", "run", "expected a run number"),
    ("10,1,sideways,0.5", "direction", "expected up or down"),
    ("10,1,up,", "deviation", "missing value"),
    ("10,1,up", None, "3 cells, the header has 4"),   # the whole row at fault: no column
    ("10,1,up,0,5", None, "5 cells, the header has 4 (a decimal comma?"),
    ("0,1,up,0.7", "run", "a second reading for target 0, run 1, up (the first on line 3)"),
])
def test_bad_rows_are_refused_with_file_line_and_column(tmp_path, capsys, row, field, message):
    path = tmp_path / "runs.csv"
    text = "target [mm],run,direction,deviation [um]\n" + "\n".join(
        f"{t},{j},{d},0.1" for j in (1, 2) for d in ("up", "down") for t in (0, 10))
    lines = text.splitlines()
    lines.insert(3, row)   # after two good rows, on line 4
    path.write_text("# comment\n" + "\n".join(lines) + "\n")
    line = refused(capsys, "iso230-2", str(path))
    assert line.startswith(f"chaincomp iso230-2: error: {path}:5: " + (f"{field}: " if field else "")), line
    assert message in line


@pytest.mark.parametrize("text,options,where,message", [
    ("target [mm],run,deviation [um]\n0,1,0.1\n", (), ":1: direction: ", "no column 'direction'"),
    ("target [mm],run,direction\n0,1,up\n", (), ":1: deviation: ", "no column 'deviation' or 'actual'"),
    ("target,run,direction,deviation [um]\n0,1,up,0.1\n", (), ":1: target: ", "no unit for column 'target'"),
    ("target [furlong],run,direction,deviation [um]\n", (), ":1: target: ", "unknown unit 'furlong'"),
    ("target [mm],run,direction,deviation [um]\n", ("--column-units", "m,um"), ":1: target: ",
     "the header says mm, --column-units says m"),
    ("target [mm],run,direction,deviation [um]\n", (), ":1: ", "no readings below the header"),
    ("target [mm],run,direction,deviation [um]\n" + "".join(f"{t},1,{d},0.1\n" for t in (0, 5) for d in ("up", "down")),
     (), ":1: run: ", "only one run"),
    ("target [mm],run,direction,deviation [um]\n" + "".join(f"5,{j},{d},0.1\n" for j in (1, 2) for d in ("up", "down")),
     (), ":2: target: ", "only one target position (5)"),
    ("# nothing\n", (), ":1: ", "no header row"),
])
def test_bad_files_are_refused(tmp_path, capsys, text, options, where, message):
    path = tmp_path / "runs.csv"
    path.write_text(text)
    line = refused(capsys, "iso230-2", str(path), *options)
    assert line.startswith(f"chaincomp iso230-2: error: {path}{where}"), line
    assert message in line


@pytest.mark.parametrize("value,message", [
    ("target", "expected FIELD=HEADER pairs"),
    ("position=Pos", "unknown field 'position'"),
    ("run=A,run=B", "run given twice"),
])
def test_bad_columns_option(tmp_path, capsys, value, message):
    path = tmp_path / "runs.csv"
    path.write_text("target [mm],run,direction,deviation [um]\n")
    line = refused(capsys, "iso230-2", str(path), "--columns", value)
    assert line.startswith("chaincomp iso230-2: error: --columns: ") and message in line


def test_bundled_example_is_synthetic_and_evaluates(capsys):
    path = RUNS
    with open(path) as f:
        assert "SYNTHETIC" in f.readline()
    doc = evaluate(capsys, path)
    assert doc["runs"] == 5 and doc["targets"] >= 5
