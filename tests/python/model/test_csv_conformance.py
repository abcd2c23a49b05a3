"""One CSV reader for every verb (issue #38 item 3): iso230-2 and laser-to-params read
``-400,1,up,0,6150`` (a decimal comma) as deviation 0 where ballbar, identify and thermal
refused it.

The corpus in tests/conformance/csv/ holds one file per case and expect.yaml what a correct
reader makes of each, worked out by hand from RFC 4180 and docs/reference/errors.md. The
reader must read each so; and every verb that reads a CSV must meet each case the same way:
the test writes the case into a valid file of that verb's format (its own columns, with the
case's separator, line ends, quotes or bad cell) and checks the verb reads the values of the
plain file, or refuses at the line of the case's fault with the corpus' message.
"""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
import yaml

from chaincomp.cli.plot import _read_replay_csv
from chaincomp.errors import ChaincompError
from chaincomp.measure import ballbar, iso230_2, table, thermal
from chaincomp.model import csvtable
from chaincomp.model.machine import load_machine
from helpers import ROOT, VMC

CORPUS = os.path.join(ROOT, "tests", "conformance", "csv")
with open(os.path.join(CORPUS, "expect.yaml"), encoding="utf-8") as _f:
    EXPECT = yaml.safe_load(_f)


def _refusal(call) -> ChaincompError | None:
    try:
        call()
    except ChaincompError as exc:
        return exc
    return None


# ----------------------------------------------------------------------------- the reader

def test_the_corpus_and_its_expectations_list_the_same_files():
    assert sorted(f for f in os.listdir(CORPUS) if f != "expect.yaml") == sorted(EXPECT)


@pytest.mark.parametrize("name", sorted(EXPECT))
def test_the_reader_reads_each_corpus_file_as_expected(name):
    path = os.path.join(CORPUS, name)
    want = EXPECT[name]
    got = {}
    header = []

    def read():
        table = csvtable.read(path)
        header[:] = table.header
        for row in table.rows:
            got[row.line] = [c if h == "note" else table.number(row, k)
                             for k, (h, c) in enumerate(zip(table.header, row.cells))]

    exc = _refusal(read)
    if "line" in want:
        assert exc is not None, f"{name} read as {got}"
        where = f"{path}:{want['line']}: " + (f"{want['column']}: " if "column" in want else "")
        assert str(exc).startswith(where) and want["message"] in str(exc), str(exc)
    else:
        assert exc is None, str(exc)
        assert header == want["header"] and got == want["rows"]


# ----------------------------------------------------------------------------- every verb

class Format:
    """A valid file of one verb's CSV: lines before the header, the header, rows; ``num`` a
    column every row holds a plain number in (and that the verb reads as one)."""

    def __init__(self, prefix, header, rows, num, read):
        self.prefix, self.header, self.rows, self.num, self.read = prefix, header, rows, num, read


def _runs_format():
    rows = [[str(t), str(j), d, f"{0.1 * (j + t / 10):.3f}"] for j in (1, 2) for d in ("up", "down") for t in (0, 10)]
    runs = lambda p: iso230_2.read_runs(p)   # noqa: E731  (laser-to-params reads through it too)
    return Format(["# X axis"], ["target [mm]", "run", "direction", "deviation [um]"], rows, 3,
                  lambda p: np.concatenate([runs(p).targets, runs(p).up.ravel(), runs(p).down.ravel()]))


def _trace_format(machine):
    rows = [[str(a), "ccw", f"{0.5 * math.cos(math.radians(a)):.6f}"] for a in range(0, 360, 30)]
    prefix = ["# plane: XY", "# axes: X, Y", "# radius: 100 mm", "# centre: 0, 0, 400 mm", "# held: Z=0 mm"]
    return Format(prefix, ["angle [deg]", "direction", "deviation [um]"], rows, 2,
                  lambda p: (lambda t: np.concatenate([t.angle, t.deviation]))(ballbar.read_trace(p, machine)))


def _setups_format(machine):
    rows = [[str(x), "10", "-100", str(x + 0.5), "10.25", "449.5"] for x in (-300, 0, 300, 100)]
    return Format([], ["X", "Y", "Z", "x", "y", "z"], rows, 0,
                  lambda p: (lambda t: np.concatenate([t.axes["X"], t.coords.ravel()]))(table.read_table(p, machine)))


def _log_format(machine):
    rows = [[str(i), f"{20 + 0.1 * i:.1f}", f"{0.2 * i:.1f}"] for i in range(12)]
    return Format([], ["time [s]", "T_a [degC]", "EZZ [um]"], rows, 1,
                  lambda p: (lambda g: np.concatenate([g.t, g.temperatures["T_a"], g.drift["EZZ"]]))(
                      thermal.read_log(p, machine)))


def _replay_format():
    head = ["event", "utime", "seq", "result"] + [f"{k}_{a}_mm" for k in ("commanded", "corrected", "correction")
                                                  for a in "XYZ"] + ["residual_point_mm"]
    rows = [[str(i), str(1_700_000_000_000_000 + 1000 * i), str(i + 1), "ok"] + ["1"] * 3 + ["1.001"] * 3
            + ["0.001"] * 3 + ["1e-9"] for i in range(5)]
    return Format([], head, rows, 4,
                  lambda p: np.concatenate([v for k, v in sorted(_read_replay_csv(p)[1].items()) if k != "ok"]))


@pytest.fixture(scope="module")
def formats():
    vmc = load_machine(VMC)
    return {"iso230-2": _runs_format(), "ballbar": _trace_format(vmc), "identify": _setups_format(vmc),
            "thermal": _log_format(vmc), "plot --replay": _replay_format()}


BAD = 1   # the row a case puts its bad cell in (the second)


def _text(f: Format, sep=",", eol="\n", cell=lambda s: s, extra=lambda r: r) -> str:
    lines = f.prefix + [sep.join(map(cell, extra(f.header)))] + [sep.join(map(cell, extra(r))) for r in f.rows]
    return eol.join(lines) + eol


def _with_cell(f: Format, value: str, sep=",") -> str:
    rows = [list(r) for r in f.rows]
    rows[BAD][f.num] = value
    return _text(Format(f.prefix, f.header, rows, f.num, f.read), sep)


def _insert(f: Format, at: int, line: str) -> str:
    lines = _text(f).split("\n")
    return "\n".join(lines[:at] + [line] + lines[at:])


# Each corpus case written into a verb's file: case -> text (or bytes) and where its fault lies
# (None: accepted; "header" or "row": the line of the header or of row BAD).
CASES = {
    "plain.csv": (lambda f: _text(f), None),
    "crlf.csv": (lambda f: _text(f, eol="\r\n"), None),
    "bom.csv": (lambda f: "\ufeff" + _text(f), None),
    "quoted-comma.csv": (lambda f: _text(f, cell=lambda s: f'"{s}"'), None),          # every cell quoted
    "empty-line.csv": (lambda f: _insert(f, len(f.prefix) + 2, "   "), None),
    "trailing-empty-line.csv": (lambda f: _text(f) + "\n\n", None),
    "no-final-line-end.csv": (lambda f: _text(f).removesuffix("\n"), None),
    "comment-lines.csv": (lambda f: _insert(f, len(f.prefix) + 1, "  # a comment, with a comma"), None),
    "spaces-around-cells.csv": (lambda f: _text(f, cell=lambda s: f' "{s}" '), None),  # quoted, spaces around
    "trailing-separator.csv": (lambda f: _text(f, extra=lambda r: list(r) + [""]), None),
    "semicolon.csv": (lambda f: _text(f, sep=";"), None),
    "tab.csv": (lambda f: _text(f, sep="\t"), None),
    "decimal-comma.csv": (lambda f: _with_cell(f, f.rows[BAD][f.num] + ",5"), "row"),
    "fewer-cells.csv": (lambda f: _text(Format(f.prefix, f.header, [r[:-1] if i == BAD else r for i, r in
                                                                     enumerate(f.rows)], f.num, f.read)), "row"),
    "semicolon-decimal-comma.csv": (lambda f: _with_cell(f, "1,5", sep=";"), "row"),
    "duplicate-column.csv": (lambda f: _text(f, extra=lambda r: list(r) + [r[0]]), "header"),
    "empty-column-name.csv": (lambda f: _text(f, extra=lambda r: [r[0], "" if r is f.header else "0"] + list(r[1:])),
                              "header"),
    "no-header.csv": (lambda f: "# only a comment\n\n", "first"),
    "empty.csv": (lambda f: "", "first"),
    "nan.csv": (lambda f: _with_cell(f, "nan"), "row"),
    "inf.csv": (lambda f: _with_cell(f, "-inf"), "row"),
    "1e400.csv": (lambda f: _with_cell(f, "1e400"), "row"),
    "underscore.csv": (lambda f: _with_cell(f, "1_000"), "row"),
    "other-digits.csv": (lambda f: _with_cell(f, "\u0661\u0662"), "row"),
    "hex.csv": (lambda f: _with_cell(f, "0x10"), "row"),
    "empty-cell.csv": (lambda f: _with_cell(f, ""), "row"),
    "huge-field.csv": (lambda f: _with_cell(f, "1" * 140_000), "row"),
    "not-utf8.csv": (lambda f: _with_cell(f, "\udce9").encode("utf-8", "surrogateescape"), "row"),
    "nul.csv": (lambda f: _with_cell(f, "4\x00"), "row"),
    "lone-cr.csv": (lambda f: _with_cell(f, "1\r2"), "row"),
    "quote-inside-unquoted.csv": (lambda f: _with_cell(f, 'x"y'), "row"),
    "text-after-quote.csv": (lambda f: _with_cell(f, '"x"y'), "row"),
    "unclosed-quote.csv": (lambda f: _with_cell(f, '"x'), "row"),
}
# Cases of text cells, and of a header's units, stay with the reader's test: not every format has a
# free text column (identify's and thermal's hold numbers only), and whether a name carries a unit
# is the format's own rule (identify reads names only; iso230-2, ballbar and thermal want units).
READER_ONLY = {"quoted-newline.csv", "quoted-crlf-newline.csv", "doubled-quote.csv", "line-separator-in-cell.csv",
               "header-units.csv"}
# where the corpus' message counts cells or names a column of its own file: the part every file shares
VERB_MESSAGE = {"decimal-comma.csv": "cells, the header has", "fewer-cells.csv": "cells, the header has",
                "duplicate-column.csv": "two columns named"}


def test_every_corpus_case_is_put_to_every_verb_or_said_why_not():
    assert set(CASES) | READER_ONLY == set(EXPECT) and not set(CASES) & READER_ONLY


@pytest.mark.parametrize("verb", ["iso230-2", "ballbar", "identify", "thermal", "plot --replay"])
@pytest.mark.parametrize("name", sorted(CASES))
def test_every_verb_meets_each_corpus_case_as_the_reader_does(tmp_path, formats, verb, name):
    f = formats[verb]
    write, fault = CASES[name]
    plain = tmp_path / "plain.csv"
    plain.write_text(_text(f), encoding="utf-8")
    data = write(f)
    path = tmp_path / "case.csv"
    path.write_bytes(data if isinstance(data, bytes) else data.encode("utf-8"))
    want = EXPECT[name]
    got = []
    exc = _refusal(lambda: got.append(f.read(str(path))))
    if fault is None:
        assert "line" not in want
        assert exc is None, str(exc)
        np.testing.assert_array_equal(got[0], f.read(str(plain)))
        return
    assert exc is not None, f"{verb} read {name} as {got}"
    line = {"first": 1, "header": len(f.prefix) + 1, "row": len(f.prefix) + 2 + BAD}[fault]
    assert exc.line == line and VERB_MESSAGE.get(name, want["message"]) in exc.message, str(exc)
    if "column" not in want:
        assert exc.field is None, str(exc)   # the whole row (or file) at fault, as the reader says


@pytest.mark.parametrize("verb", ["iso230-2", "laser-to-params"])
def test_a_decimal_comma_in_the_runs_is_refused_and_nothing_written(tmp_path, verb):
    """The issue's row: laser-to-params wrote a compensation table from '-400,1,up,0,6150' read as 0."""
    from helpers import RUNS, machine_path, one_error_line, run_in_process
    lines = open(RUNS, encoding="utf-8").read().split("\n")
    k = next(i for i, line in enumerate(lines) if line and not line.startswith("#")) + 1   # the first reading
    cells = lines[k].split(",")
    lines[k] = ",".join(cells[:-1] + [cells[-1].replace(".", ",")])   # 0.6150 -> 0,6150: five cells
    runs = tmp_path / "runs.csv"
    runs.write_text("\n".join(lines), encoding="utf-8")
    out = tmp_path / "out.yaml"
    first, args = ([machine_path("five_axis_ac")], ["--error", "EXX", "-o", str(out)]) if verb == "laser-to-params" \
        else ([], ["--format", "json"])
    one_error_line(run_in_process(verb, *first, str(runs), *args), verb,
                   f"{runs}:{k + 1}: 5 cells, the header has 4 (a decimal comma? write decimals with a point)")
    assert not out.exists()
