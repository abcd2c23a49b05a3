"""The replay's inputs: a folder for a log, and the replay CSV that plot --replay reads (faults by
file, line and field, a byte order mark, time going back)."""

from __future__ import annotations

import os

import pytest

from helpers import machine_path, ROOT, one_error_line, refused, run_in_process, run_main


MACHINE = machine_path("five_axis_ac")
DEMO = os.path.join(ROOT, "configs", "params", "five_axis_ac-demo.yaml")


def test_replay_input_that_is_a_folder_says_so(tmp_path):
    one_error_line(run_in_process("replay", MACHINE, str(tmp_path), "--params", DEMO, "--csv", str(tmp_path / "o.csv")),
                   "replay", "is a folder")


def _replay_csv(tmp_path, rows=None, header=None) -> str:
    """A replay CSV of a three-axis machine in the columns 'chaincomp replay --csv' writes."""
    axes = ("X", "Y", "Z")
    head = header or (["event", "utime", "seq", "result"] + [f"{k}_{a}_mm" for k in ("commanded", "corrected",
                                                                                       "correction") for a in axes]
                      + ["residual_point_mm"])
    rows = _replay_rows(lambda r: None) if rows is None else rows
    path = tmp_path / "replay.csv"
    path.write_text("\n".join(",".join(r) for r in [head] + rows) + "\n")
    return str(path)


def _replay_rows(change):
    """Five corrected records; change(rows) edits them in place."""
    rows = [[str(i), str(1_700_000_000_000_000 + 1000 * i), str(i + 1), "ok"] + ["1"] * 3 + ["1.001"] * 3
            + ["0.001"] * 3 + ["1e-9"] for i in range(5)]
    change(rows)
    return rows


@pytest.mark.parametrize("change,where", [
    # a row cut short read as a record without a result: counted as rejected, silently
    (lambda r: r.__setitem__(2, r[2][:3]), ":4: 3 cells, the header has 14"),
    (lambda r: r[2].append("7"), ":4: 15 cells, the header has 14 (a decimal comma?"),
    # 1e308 mm reached the exact model
    (lambda r: r[1].__setitem__(4, "1e308"), ":3: commanded_X_mm: '1e308' is beyond 1e+15 in magnitude"),
    (lambda r: r[1].__setitem__(1, "-5"), ":3: utime: expected whole microseconds from 0 to 2^62, got '-5'"),
    (lambda r: r[1].__setitem__(1, "1.5"), ":3: utime: expected whole microseconds"),
])
def test_replay_csv_faults(capsys, tmp_path, change, where):
    path = _replay_csv(tmp_path, _replay_rows(change))
    refused(capsys, "plot", "--replay", path, "-o", tmp_path / "r.png", match=path + where)


def test_replay_csv_header_faults(capsys, tmp_path):
    head = ["event", "utime", "seq", "result", "commanded_X_mm", "corrected_X_mm", "correction_X_mm",
            "residual_point_mm", "utime"]
    path = _replay_csv(tmp_path, [["0", "1", "1", "ok", "1", "1", "0", "0", "1"]], head)
    refused(capsys, "plot", "--replay", path, "-o", tmp_path / "r.png", match=path + ":1: two columns named 'utime'")


def test_replay_csv_with_a_byte_order_mark_and_utime_first(capsys, tmp_path):
    """A spreadsheet's BOM glued to the first column's name: 'no utime column' before."""
    path = _replay_csv(tmp_path)
    lines = open(path).read().splitlines()
    cols = [line.split(",") for line in lines]
    with open(path, "w", encoding="utf-8-sig") as f:
        f.write("\n".join(",".join([c[1], c[0]] + c[2:]) for c in cols) + "\n")
    code, _, err = run_main(capsys, "plot", "--replay", path, "-o", tmp_path / "r.png")
    assert code == 0, err


@pytest.mark.slow
def test_replay_csv_time_going_back_warns(capsys, tmp_path):
    path = _replay_csv(tmp_path, _replay_rows(lambda r: r[3].__setitem__(1, "1600000000000000")))
    code, _, err = run_main(capsys, "plot", "--replay", path, "-o", tmp_path / "r.png")
    assert code == 0 and f"{path}:5: utime goes back" in err, err
