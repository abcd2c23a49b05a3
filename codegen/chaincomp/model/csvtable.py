"""The one reader of the CSV files the verbs take (iso230-2 and laser-to-params runs, identify
and simulate-measurements set-ups, ballbar traces, thermal logs, plot's replay CSV): every verb
reads its file with ``read`` and then only says which columns it needs, so that a file one verb
refuses no other reads as something else (a decimal comma made ``-400,1,up,0,6150`` a row of
five cells that ballbar refused and iso230-2 read as deviation 0).

The rules, one for all (the corpus in tests/conformance/csv/ holds a file per case):

- UTF-8, a leading byte order mark ignored; lines end at LF or CRLF, and nowhere else (not at
  U+2028 or a form feed, which are text); a NUL or a CR not followed by LF is refused at its line;
- lines that are blank or whose first character (after spaces) is ``#`` are comments outside a
  quoted cell; line numbers count them;
- the first other line is the header; its separator is ``;`` where it holds more semicolons than
  commas, a tab where it holds tabs and no comma, otherwise ``,``; every column has a name, no
  name twice (empty names at its end are trailing separators, dropped);
- cells per RFC 4180: a cell in double quotes may hold the separator, a line break and doubled
  quotes; spaces and tabs around a cell are not part of it; a quote inside an unquoted cell, or
  text after a closing quote, is refused;
- every row has exactly the header's number of cells: more (a decimal comma) or fewer are
  refused at the row's line; only empty cells past the header's (a spreadsheet's trailing
  separators) are dropped, as they hold nothing;
- at most ``max_rows`` rows, ``MAX_COLUMNS`` columns, ``MAX_FIELD`` characters a cell;
- a cell read as a number follows ``numbers.parse_number`` (plain finite decimals).

Errors are ``FILE:LINE: COLUMN: message`` (no column where the whole row is at fault). The
header is read first, the rows as the verb iterates them: the fault reported is the file's
first, whether the reader's or the verb's.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass, field

from ..errors import ChaincompError
from .numbers import parse_number
from .yamlsource import MAX_FILE_BYTES, read_text

MAX_FIELD = 131_072        # characters a cell (the limit Python's csv module had)
MAX_COLUMNS = 1024
MAX_ROWS = 2_000_000
_NOT_TEXT = re.compile(r"\x00|\r(?!\n)")   # a binary file; an old Mac line end (read as one line by some, two by others)
_DECIMAL_COMMA = re.compile(r"\s*[+-]?[0-9]+,[0-9]+\s*")
_HEADER_UNIT = re.compile(r"^(.*?)\s*[\[(]\s*([^\])]+?)\s*[\])]\s*$")
_BLANK = " \t"


@dataclass(slots=True)
class Row:
    line: int            # the line the row starts on
    cells: list[str]


@dataclass
class Table:
    """A CSV file's header, read; its rows are read as they are iterated (once), so that a log
    of millions of rows is never held as text cells."""
    path: str
    line: int                        # the header's line
    header: list[str]                # column names as written (units and all), without surrounding spaces
    rows: Iterator[Row]
    comments: list[tuple[int, str]] = field(default_factory=list)   # (line, text) of the '#' lines so far
    separator: str = ","
    lines_left: int = 0              # lines below the header: at least the rows to come

    def fail(self, message: str, line: int | None = None, column: str | None = None):
        raise ChaincompError(message, self.path, line, column)

    def number(self, row: Row, k: int, column: str | None = None) -> float:
        """Cell ``k`` of ``row`` as a number; an empty cell is a missing value. Errors name
        ``column`` (the verb's name for it) or else the header's."""
        text, column = row.cells[k], column or self.header[k]
        if not text:
            self.fail("missing value", row.line, column)
        try:
            return parse_number(text)
        except ValueError as exc:
            hint = " (a decimal comma? write decimals with a point)" if _DECIMAL_COMMA.fullmatch(text) else ""
            self.fail(f"{exc}{hint}", row.line, column)


def split_unit(name: str) -> tuple[str, str | None]:
    """'target [mm]' or 'target (mm)' -> ('target', 'mm'); 'run' -> ('run', None)."""
    m = _HEADER_UNIT.match(name.strip())
    return (m.group(1).strip(), m.group(2)) if m else (name.strip(), None)


def read(path: str, max_rows: int = MAX_ROWS, max_bytes: int = MAX_FILE_BYTES,
         example: str = "") -> Table:
    """The table in a CSV file (the module's rules): the header now, the rows as they are
    iterated; ``example`` is a header to suggest when there is none."""
    text = read_text(path, limit=max_bytes).removeprefix("\ufeff")   # the byte order mark spreadsheets write
    bad = _NOT_TEXT.search(text)
    if bad:
        what = "a carriage return not followed by a line feed (lines end in LF or CRLF)" if bad.group() == "\r" \
            else "a NUL character: not a text file"
        raise ChaincompError(what, path, text.count("\n", 0, bad.start()) + 1)
    table = Table(path, 0, [], iter(()))
    records = _records(text, table)
    for line, cells in records:
        while len(cells) > 1 and not cells[-1]:
            cells.pop()   # empty names at the end: a spreadsheet's trailing separators
        _check_header(cells, path, line)
        table.header, table.line = cells, line
        table.lines_left = text.count("\n") + 1 - line
        table.rows = _rows(records, table, max_rows)
        return table
    raise ChaincompError("no header row" + (f" (expected e.g. {example!r})" if example else ""), path, 1)


def _rows(records, table: Table, max_rows: int) -> Iterator[Row]:
    width, n = len(table.header), 0
    for line, cells in records:
        if len(cells) > width and not any(cells[width:]):
            del cells[width:]   # empty cells past the header: a spreadsheet's trailing separators
        if len(cells) != width:
            hint = " (a decimal comma? write decimals with a point)" if len(cells) > width and table.separator == "," \
                else ""
            table.fail(f"{len(cells)} cell{'s' if len(cells) != 1 else ''}, the header has {width}{hint}", line)
        if n == max_rows:
            table.fail(f"more than {max_rows} rows", line)
        n += 1
        yield Row(line, cells)


def _records(text: str, table: Table) -> Iterator[tuple[int, list[str]]]:
    """(line, cells) of each record that is not a comment or blank; the separator is set by
    the first."""
    lines = _lines(text)
    for start, line in lines:
        content = line.lstrip(_BLANK)
        if not content:
            continue
        if content[0] == "#":
            table.comments.append((start, line))
            continue
        if not table.header:
            table.separator = ";" if line.count(";") > line.count(",") else \
                "\t" if "\t" in line and "," not in line else ","
        long = len(line) > MAX_FIELD
        if '"' in line:
            cells, long = _quoted(start, line, lines, table.separator, table.path), True
        elif " " in line or "\t" in line:
            cells = [c.strip(_BLANK) for c in line.split(table.separator)]
        else:
            cells = line.split(table.separator)
        if long:
            for k, c in enumerate(cells):
                if len(c) > MAX_FIELD:
                    table.fail(f"a cell of {len(c)} characters: at most {MAX_FIELD}", start,
                               table.header[k] if k < len(table.header) else None)
        yield start, cells


def _lines(text: str) -> Iterator[tuple[int, str]]:
    """(number, line) at LF or CRLF only: str.splitlines would also split at U+2028, a form feed, ..."""
    at, number = 0, 0
    while at <= len(text):
        end = text.find("\n", at)
        end = len(text) if end < 0 else end
        number += 1
        yield number, text[at:end].removesuffix("\r")
        at = end + 1


def _check_header(cells: list[str], path: str, line: int) -> None:
    if len(cells) > MAX_COLUMNS:
        raise ChaincompError(f"{len(cells)} columns: at most {MAX_COLUMNS}", path, line)
    seen: dict[str, int] = {}
    for k, name in enumerate(cells, 1):
        if not name:
            raise ChaincompError(f"column {k} has no name", path, line)
        if name in seen:
            raise ChaincompError(f"two columns named {name!r} (columns {seen[name]} and {k})", path, line)
        seen[name] = k


def _quoted(first: int, text: str, lines, sep: str, path: str) -> list[str]:
    """The cells of the record that starts on line ``first`` (``text``) and holds a quote
    (RFC 4180: a quoted cell may run over line ends, taken from ``lines``)."""
    number = first
    cells, j = [], 0
    while True:
        while j < len(text) and text[j] in _BLANK and text[j] != sep:
            j += 1
        if j < len(text) and text[j] == '"':
            parts, j = [], j + 1
            while True:
                q = text.find('"', j)
                if q < 0:   # the cell goes on past the line end
                    parts += [text[j:], "\n"]
                    number, text = next(lines, (None, None))
                    if text is None:
                        raise ChaincompError("a quoted cell is not closed (a quote missing?)", path, first)
                    j = 0
                    continue
                parts.append(text[j:q])
                if text.startswith('"', q + 1):   # "" is one quote
                    parts.append('"')
                    j = q + 2
                    continue
                j = q + 1
                break
            cell = "".join(parts)
            while j < len(text) and text[j] in _BLANK and text[j] != sep:
                j += 1
            if j < len(text) and text[j] != sep:
                raise ChaincompError(f"text after a closing quote: {text[j:j + 20]!r} (a quote inside a quoted cell "
                                     "is written twice: \"\")", path, number)
        else:
            end = text.find(sep, j)
            end = len(text) if end < 0 else end
            cell = text[j:end].strip(_BLANK)
            if '"' in cell:
                raise ChaincompError(f"a quote inside the unquoted cell {cell[:40]!r}: quote the whole cell and "
                                     "write the quote twice (\"a \"\"b\"\"\")", path, number)
            j = end
        cells.append(cell)
        if j >= len(text):
            return cells
        j += 1   # past the separator
