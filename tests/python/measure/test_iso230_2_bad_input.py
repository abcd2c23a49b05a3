"""chaincomp iso230-2's bad input: spreads that overflow, targets beyond the value bound or not
positions, two fields from one column, cells beyond the CSV field limit."""

from helpers import RUNS, one_error_line, run_cli, run_in_process


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


def test_iso230_2_deviations_whose_spread_overflows_are_refused_in_text_too(tmp_path):
    # ±1.7e308 um: finite as written, but s = inf; the text report used to print it (exit 0)
    # while --format json refused it without naming the file
    p = runs_csv(tmp_path, "ovf.csv", lambda r, dev: "1.7e308" if r % 2 else "-1.7e308")
    for fmt in ("text", "json"):
        one_error_line(run_cli("iso230-2", str(p), "--format", fmt, check=False), "iso230-2", "ovf.csv:", "deviation",
                       "1e+15")   # a real process: the exit path


def test_iso230_2_target_beyond_the_value_bound_is_refused(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text(open(RUNS, encoding="utf-8").read().replace("\n-400,", "\n-1e300,"), encoding="utf-8")
    one_error_line(run_in_process("iso230-2", str(p)), "iso230-2", "t.csv:", "target", "1e+15")


def test_iso230_2_targets_must_be_positions(tmp_path):
    # targets in ppm or '1' (a ratio) were evaluated as if they were positions along an axis
    text = open(RUNS, encoding="utf-8").read()
    for unit in ("ppm", "1"):
        p = tmp_path / "r.csv"
        p.write_text(text.replace("target [mm]", f"target [{unit}]"), encoding="utf-8")
        one_error_line(run_in_process("iso230-2", str(p)), "iso230-2", "r.csv:", "target", "length or an angle")


def test_iso230_2_two_fields_from_one_column_are_refused():
    # --columns actual=target read the targets as the actual positions: every deviation 0, exit 0
    one_error_line(run_in_process("iso230-2", RUNS, "--columns", "actual=target [mm]"), "iso230-2",
                   "five_axis_ac-X-positioning.csv:", "actual", "target", "column 1")


def test_iso230_2_a_cell_beyond_the_csv_field_limit_is_bad_input(tmp_path):
    # Python's csv module raises its own Error past 131072 characters a field: exit 3 (internal error)
    p = tmp_path / "long.csv"
    lines = open(RUNS, encoding="utf-8").read().splitlines()
    p.write_text("\n".join(lines[:6] + ["-400,1,up," + "1" * 200_000] + lines[6:]) + "\n", encoding="utf-8")
    one_error_line(run_in_process("iso230-2", str(p)), "iso230-2", "long.csv:7:")
