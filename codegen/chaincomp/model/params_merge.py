"""A params file edited in place: one error's entry replaced, or added at the end of ``values``,
every other line (comments, layout, line ends) kept as the user wrote it. laser-to-params and
ballbar --merge write their results this way."""

from __future__ import annotations

import re

from ..errors import ChaincompError
from .machine import Machine
from .params import load_params
from .yamlsource import load_yaml, read_text


def merge(path: str, machine: Machine, error: str, make_entry) -> str:
    """The text of params file ``path`` with ``error``'s entry replaced (or added at the end of
    ``values``) by ``make_entry(indent)``: every other line stays as it was."""
    load_params(path, machine)   # a broken file is reported as itself, line and field
    doc = load_yaml(path)
    values = doc["values"]
    text = read_text(path)
    lines = text.splitlines()
    eol = "\r\n" if "\r\n" in text else "\n"   # a file written on Windows stays so

    def fail(msg, line):
        raise ChaincompError(f"--merge: {msg}", path, line, "values")

    if not re.fullmatch(r"values:\s*(#.*)?", lines[doc.lines["values"] - 1]):
        fail("'values' must be a block mapping (one entry per line) to merge into", doc.lines["values"])
    starts = sorted([values.lines[k] for k in values] + [doc.lines[k] for k in doc if k != "values"] +
                    [i for i, t in enumerate(lines, 1) if re.match(r"(\.\.\.|---)(\s|$)", t)])  # document markers

    def end_of(start: int, indent: int) -> int:
        """0-based index past the entry starting on line ``start``: up to the next key, less the
        comments and blank lines before it (they belong to it)."""
        end = next((s - 1 for s in starts if s > start), len(lines))
        while end > start and (not lines[end - 1].strip() or
                               (lines[end - 1].lstrip().startswith("#") and
                                len(lines[end - 1]) - len(lines[end - 1].lstrip()) <= indent)):
            end -= 1
        return end

    for k in values:
        text = lines[values.lines[k] - 1]
        if not re.match(rf"\s+{re.escape(str(k))}\s*:", text):
            fail(f"entry {k} must be written as '  {k}: ...' on its own line to merge into", values.lines[k])
    first_key = lines[values.lines[next(iter(values))] - 1]   # load_params refused an empty 'values'
    indent = len(first_key) - len(first_key.lstrip())
    if error in values:
        start = values.lines[error]
        # the comment line laser-to-params wrote above an earlier table goes with it
        first = start - 1
        if first > 0 and lines[first - 1].strip().startswith(f"# {error}: ISO 230-2"):
            first -= 1
        new = lines[:first] + make_entry(" " * indent) + lines[end_of(start, indent):]
    else:
        last = max(values.lines[k] for k in values)
        at = end_of(last, indent)
        new = lines[:at] + make_entry(" " * indent) + lines[at:]
    return eol.join(new) + eol
