"""chaincomp laser-to-params' bad input and its merge into a params file a user keeps (a document
end marker, CRLF line ends, targets equal as written)."""


import yaml

from helpers import machine_path, RUNS, one_error_line, run_in_process


MACHINE = machine_path("five_axis_ac")


def test_laser_to_params_a_file_name_cannot_write_a_value(tmp_path):
    # the CSV's name goes into a comment line of the output: its line breaks used to end the
    # comment, and the rest of the name was read as an entry (here EZX = 999 um)
    name = tmp_path / "x\n  EZX: 999 um\n  #\u2028  EYZ: 5 um\n.csv"
    name.write_text(open(RUNS, encoding="utf-8").read(), encoding="utf-8")
    base = tmp_path / "p.yaml"
    base.write_text("machine: five_axis_ac\nvalues:\n  EYX: 1 um\n", encoding="utf-8")
    for merge in (["--merge", str(base)], []):
        out = tmp_path / f"o{len(merge)}.yaml"
        res = run_in_process("laser-to-params", MACHINE, str(name), "--error", "EXX", "-o", str(out), *merge)
        assert res.returncode == 0, res.stderr
        values = yaml.safe_load(out.read_text(encoding="utf-8"))["values"]
        assert sorted(values) == (["EXX", "EYX"] if merge else ["EXX"]), values


def test_laser_to_params_merges_into_a_file_ending_with_a_document_end_marker(tmp_path):
    # the new entry used to go after '...', and the output was refused as not loading back,
    # naming the output (which is not there) instead of anything the user wrote
    base = tmp_path / "p.yaml"
    base.write_text("---\nmachine: five_axis_ac\nvalues:\n  EYX: 1 um\n...\n", encoding="utf-8")
    out = tmp_path / "o.yaml"
    res = run_in_process("laser-to-params", MACHINE, RUNS, "--error", "EXX", "-o", str(out), "--merge", str(base))
    assert res.returncode == 0, res.stderr
    text = out.read_text(encoding="utf-8")
    assert text.startswith("---\nmachine: five_axis_ac\nvalues:\n  EYX: 1 um\n") and text.endswith("\n...\n")
    assert sorted(yaml.safe_load(text)["values"]) == ["EXX", "EYX"]


def test_laser_to_params_merge_keeps_crlf_line_ends(tmp_path):
    # "every other line is kept byte for byte": a Windows-written file's \r\n became \n
    base = tmp_path / "p.yaml"
    base.write_bytes(b"# from the shop PC\r\nmachine: five_axis_ac\r\nvalues:\r\n  EYX: 1 um\r\n")
    out = tmp_path / "o.yaml"
    res = run_in_process("laser-to-params", MACHINE, RUNS, "--error", "EXX", "-o", str(out), "--merge", str(base))
    assert res.returncode == 0, res.stderr
    data = out.read_bytes()
    assert data.startswith(base.read_bytes()) and b"\n" not in data.replace(b"\r\n", b"")


def test_laser_to_params_targets_equal_as_written_are_refused_in_the_csv(tmp_path):
    # -400 and -399.99999999999 are one knot at the table's 10 digits: the refusal named the
    # output file (not written) and a line in it, not the CSV
    text = open(RUNS, encoding="utf-8").read().replace("\n-380,", "\n-399.99999999999,")
    p = tmp_path / "close.csv"
    p.write_text(text, encoding="utf-8")
    line = 1 + text.splitlines().index(next(t for t in text.splitlines() if t.startswith("-399.99999999999,")))
    out = tmp_path / "o.yaml"
    res = run_in_process("laser-to-params", MACHINE, str(p), "--error", "EXX", "-o", str(out))
    one_error_line(res, "laser-to-params", f"close.csv:{line}: target", "-400")
    assert not out.exists()


def test_laser_to_params_error_that_is_an_axis_reads_right():
    one_error_line(run_in_process("laser-to-params", MACHINE, RUNS, "--error", "X", "-o", "/tmp/never.yaml"),
                   "laser-to-params", "--error: 'X' is an axis of five_axis_ac, not an error")
