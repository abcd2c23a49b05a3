"""Bad input found by a hunt over the verbs added in 2026-12 (iso230-2, laser-to-params, build,
lint, status, replay, dh elements): each test is one case that used to give a traceback, a
silent wrong value or a message without file, line and field."""

import os
import subprocess
import sys

import yaml

from conftest import cli

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
RUNS = os.path.join(ROOT, "configs", "measurements", "five_axis_ac-X-positioning.csv")


def run(*args):
    """In this process (cli.main.main), without a process's ~1 s of start-up."""
    return cli(*args, check=False)


def run_process(*args, cwd=ROOT, timeout=60):
    return subprocess.run([sys.executable, "-m", "chaincomp.cli.main", *args], capture_output=True,
                          text=True, cwd=cwd, timeout=timeout)


def runs_csv(tmp_path, name, value_of_row):
    """The bundled runs with each reading's deviation replaced by value_of_row(run)."""
    out = ["target [mm],run,direction,deviation [um]"]
    for line in open(RUNS, encoding="utf-8").read().splitlines():
        if line.startswith("#") or line.startswith("target") or not line.strip():
            continue
        target, r, d, dev = line.split(",")
        out.append(f"{target},{r},{d},{value_of_row(int(r), dev)}")
    p = tmp_path / name
    p.write_text("\n".join(out) + "\n", encoding="utf-8")
    return p


def one_error_line(res, verb, *words):
    assert res.returncode == 2, (res.returncode, res.stdout[-500:], res.stderr[-2000:])
    assert "Traceback" not in res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"chaincomp {verb}: error: "), res.stderr
    for w in words:
        assert w in lines[0], (w, lines[0])
    return lines[0]


def test_iso230_2_deviations_whose_spread_overflows_are_refused_in_text_too(tmp_path):
    # ±1.7e308 um: finite as written, but s = inf; the text report used to print it (exit 0)
    # while --format json refused it without naming the file
    p = runs_csv(tmp_path, "ovf.csv", lambda r, dev: "1.7e308" if r % 2 else "-1.7e308")
    for fmt in ("text", "json"):
        one_error_line(run_process("iso230-2", str(p), "--format", fmt), "iso230-2", "ovf.csv:", "deviation",
                       "1e+15")   # a real process: the exit path


def test_iso230_2_target_beyond_the_value_bound_is_refused(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text(open(RUNS, encoding="utf-8").read().replace("\n-400,", "\n-1e300,"), encoding="utf-8")
    one_error_line(run("iso230-2", str(p)), "iso230-2", "t.csv:", "target", "1e+15")


def arm(tmp_path, name, symbols, chain):
    axes = "".join(f"  - {{name: q{i}, role: axis, unit: deg, limits: [-360, 360]}}\n" for i in (1, 2))
    p = tmp_path / f"{name}.yaml"
    p.write_text(f"name: {name}\nsymbols:\n{axes}{symbols}chain:\n{chain}"
                 "tool:\n  point: [0, 0, 0]\n  direction: [0, 0, 1]\n", encoding="utf-8")
    return p


def test_auto_error_colliding_with_a_declared_error_is_refused(tmp_path):
    # joint 1's auto dd1 and joint 2's named dd1 used to be one symbol, silently: two physical
    # errors that calibration could never tell apart
    p = arm(tmp_path, "collide", "  - {name: dd1, role: error, unit: um}\n",
            "  - {dh: {theta: q1, d: 5, a: 10, alpha: pi/2}, errors: auto}\n"
            "  - {dh: {theta: q2, d: 0, a: 10, alpha: 0}, errors: {d: dd1}}\n")
    line = one_error_line(run("lint", str(p)), "lint", "collide.yaml:7:", "chain[0].errors.d", "dd1", "line 5")
    assert "auto" in line


def test_named_error_equal_to_an_earlier_auto_name_is_refused(tmp_path):
    p = arm(tmp_path, "collide2", "",
            "  - {dh: {theta: q1, d: 5, a: 10, alpha: pi/2}, errors: auto}\n"
            "  - {dh: {theta: q2, d: 0, a: 10, alpha: 0}, errors: {d: dd1}}\n")
    one_error_line(run("lint", str(p)), "lint", "collide2.yaml:7:", "chain[1].errors.d", "dd1", "line 6")


def test_status_empty_url_is_refused():
    # an empty --url used to open liblcm's default (LCM_DEFAULT_URL, else UDP multicast) without
    # a word; the environment here keeps even that in-process
    env = dict(os.environ, LCM_DEFAULT_URL="memq://")
    res = subprocess.run([sys.executable, "-m", "chaincomp.cli.main", "status", "--once", "--timeout", "0.1",
                          "--url", " "], capture_output=True, text=True, cwd=ROOT, timeout=60, env=env)
    one_error_line(res, "status", "--url", "empty")


MACHINE = os.path.join(ROOT, "configs", "machines", "five_axis_ac.yaml")
DEMO = os.path.join(ROOT, "configs", "params", "five_axis_ac-demo.yaml")


def test_replay_input_that_is_a_folder_says_so(tmp_path):
    one_error_line(run("replay", MACHINE, str(tmp_path), "--params", DEMO, "--csv", str(tmp_path / "o.csv")),
                   "replay", "is a folder")


def test_laser_to_params_a_file_name_cannot_write_a_value(tmp_path):
    # the CSV's name goes into a comment line of the output: its line breaks used to end the
    # comment, and the rest of the name was read as an entry (here EZX = 999 um)
    name = tmp_path / "x\n  EZX: 999 um\n  #\u2028  EYZ: 5 um\n.csv"
    name.write_text(open(RUNS, encoding="utf-8").read(), encoding="utf-8")
    base = tmp_path / "p.yaml"
    base.write_text("machine: five_axis_ac\nvalues:\n  EYX: 1 um\n", encoding="utf-8")
    for merge in (["--merge", str(base)], []):
        out = tmp_path / f"o{len(merge)}.yaml"
        res = run("laser-to-params", str(name), "--machine", MACHINE, "--error", "EXX", "-o", str(out), *merge)
        assert res.returncode == 0, res.stderr
        values = yaml.safe_load(out.read_text(encoding="utf-8"))["values"]
        assert sorted(values) == (["EXX", "EYX"] if merge else ["EXX"]), values


def test_laser_to_params_merges_into_a_file_ending_with_a_document_end_marker(tmp_path):
    # the new entry used to go after '...', and the output was refused as not loading back,
    # naming the output (which is not there) instead of anything the user wrote
    base = tmp_path / "p.yaml"
    base.write_text("---\nmachine: five_axis_ac\nvalues:\n  EYX: 1 um\n...\n", encoding="utf-8")
    out = tmp_path / "o.yaml"
    res = run("laser-to-params", RUNS, "--machine", MACHINE, "--error", "EXX", "-o", str(out), "--merge", str(base))
    assert res.returncode == 0, res.stderr
    text = out.read_text(encoding="utf-8")
    assert text.startswith("---\nmachine: five_axis_ac\nvalues:\n  EYX: 1 um\n") and text.endswith("\n...\n")
    assert sorted(yaml.safe_load(text)["values"]) == ["EXX", "EYX"]


def test_laser_to_params_merge_keeps_crlf_line_ends(tmp_path):
    # "every other line is kept byte for byte": a Windows-written file's \r\n became \n
    base = tmp_path / "p.yaml"
    base.write_bytes(b"# from the shop PC\r\nmachine: five_axis_ac\r\nvalues:\r\n  EYX: 1 um\r\n")
    out = tmp_path / "o.yaml"
    res = run("laser-to-params", RUNS, "--machine", MACHINE, "--error", "EXX", "-o", str(out), "--merge", str(base))
    assert res.returncode == 0, res.stderr
    data = out.read_bytes()
    assert data.startswith(base.read_bytes()) and b"\n" not in data.replace(b"\r\n", b"")


def test_iso230_2_targets_must_be_positions(tmp_path):
    # targets in ppm or '1' (a ratio) were evaluated as if they were positions along an axis
    text = open(RUNS, encoding="utf-8").read()
    for unit in ("ppm", "1"):
        p = tmp_path / "r.csv"
        p.write_text(text.replace("target [mm]", f"target [{unit}]"), encoding="utf-8")
        one_error_line(run("iso230-2", str(p)), "iso230-2", "r.csv:", "target", "length or an angle")


def test_iso230_2_two_fields_from_one_column_are_refused():
    # --columns actual=target read the targets as the actual positions: every deviation 0, exit 0
    one_error_line(run("iso230-2", RUNS, "--columns", "actual=target [mm]"), "iso230-2",
                   "five_axis_ac-X-positioning.csv:", "actual", "target", "column 1")


def test_laser_to_params_targets_equal_as_written_are_refused_in_the_csv(tmp_path):
    # -400 and -399.99999999999 are one knot at the table's 10 digits: the refusal named the
    # output file (not written) and a line in it, not the CSV
    text = open(RUNS, encoding="utf-8").read().replace("\n-380,", "\n-399.99999999999,")
    p = tmp_path / "close.csv"
    p.write_text(text, encoding="utf-8")
    line = 1 + text.splitlines().index(next(t for t in text.splitlines() if t.startswith("-399.99999999999,")))
    out = tmp_path / "o.yaml"
    res = run("laser-to-params", str(p), "--machine", MACHINE, "--error", "EXX", "-o", str(out))
    one_error_line(res, "laser-to-params", f"close.csv:{line}: target", "-400")
    assert not out.exists()


def test_build_never_copies_the_library_over_its_machine_file(tmp_path):
    # build M -o DIR writes DIR/NAME.so: a machine file of that very name was overwritten by the library
    m = tmp_path / "tiny.so"
    text = ("name: tiny\nsymbols:\n  - {name: X, role: axis, unit: mm, limits: [-1, 1]}\n"
            "  - {name: EXX, role: error, unit: um}\nchain:\n  - {translate: [X + EXX, 0, 0]}\n"
            "tool:\n  point: [0, 0, 0]\n  direction: [0, 0, 1]\n")
    m.write_text(text, encoding="utf-8")
    env = dict(os.environ, XDG_CACHE_HOME=str(tmp_path / "cache"))
    res = subprocess.run([sys.executable, "-m", "chaincomp.cli.main", "build", str(m), "-o", str(tmp_path)],
                         capture_output=True, text=True, cwd=ROOT, timeout=300, env=env)
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
    last = res.stderr.strip().splitlines()[-1]   # after the build's progress lines
    assert last.startswith("chaincomp build: error: -o ") and "tiny.so" in last and "input" in last, last
    assert m.read_text(encoding="utf-8") == text


def test_laser_to_params_error_that_is_an_axis_reads_right():
    one_error_line(run("laser-to-params", RUNS, "--machine", MACHINE, "--error", "X", "-o", "/tmp/never.yaml"),
                   "laser-to-params", "--error: 'X' is an axis of five_axis_ac, not an error")


def test_iso230_2_a_cell_beyond_the_csv_field_limit_is_bad_input(tmp_path):
    # Python's csv module raises its own Error past 131072 characters a field: exit 3 (internal error)
    p = tmp_path / "long.csv"
    lines = open(RUNS, encoding="utf-8").read().splitlines()
    p.write_text("\n".join(lines[:6] + ["-400,1,up," + "1" * 200_000] + lines[6:]) + "\n", encoding="utf-8")
    one_error_line(run("iso230-2", str(p)), "iso230-2", "long.csv:7:")


def test_identify_a_cell_beyond_the_csv_field_limit_is_bad_input(tmp_path):
    p = tmp_path / "meas.csv"
    p.write_text("X,Y,Z,x\n" + "1" * 200_000 + ",0,0,0\n", encoding="utf-8")
    res = run("identify", os.path.join(ROOT, "configs", "machines", "vmc_xyz.yaml"), str(p))
    one_error_line(res, "identify", "meas.csv:2:")


def test_an_expression_of_the_wrong_shape_is_named_plainly(tmp_path):
    # the loader's own class name leaked: "expected a number or an expression, got LineList"
    p = arm(tmp_path, "shape", "", "  - {dh: {theta: q1, d: 0, a: 1, alpha: 0}}\n  - {beta: [1], errors: auto}\n")
    line = one_error_line(run("lint", str(p)), "lint", "shape.yaml:7:", "chain[1].beta", "a list")
    assert "LineList" not in line
