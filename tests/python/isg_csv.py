"""An independent reader of ISG CSV parameter files of ISG's volumetric compensation
(Beckhoff TwinCAT CNC TF5280), written for the tests of chaincomp export from ISG's kernel
manual (isg-stuttgart.de/fileadmin/kernel/kernel-html/en-GB/):

- 296429067 "ISG CSV format": a header names the columns (arguments and parameters), the
  records follow, "//" starts a comment, "#" a file break after which a new header comes;
  a block may depend on several arguments (records of "Z X EXX ..." for Z = 0, then 100);
- 296426379 "Units of measure": parameter values in mm (offsets) or rad (angles),
  arguments X, Y, Z in mm and A, B, C in degrees;
- 296423819 "List of parameters supported": component errors EXX..ECC, position errors
  X0X..C0C;
- interpolation GRID (1218769547's example list): linear between the records, per argument
  (a regular grid of several arguments: multilinear).
"""

import re

import numpy as np

ARGUMENTS = ("X", "Y", "Z", "A", "B", "C")
COMPONENT = re.compile(r"^E[XYZABC][XYZABC]$")
POSITION = re.compile(r"^[XYZABC]0[XYZABC]$")


class Block:
    def __init__(self, header, rows):
        self.arguments = [h for h in header if h in ARGUMENTS]
        self.parameters = [h for h in header if h not in ARGUMENTS]
        assert header[:len(self.arguments)] == self.arguments, f"arguments first: {header}"
        for p in self.parameters:
            assert COMPONENT.match(p) or POSITION.match(p), f"not an ISG parameter name: {p}"
        self.rows = np.array(rows, float).reshape(-1, len(header))
        n = len(self.arguments)
        self.grid = [np.unique(self.rows[:, k]) for k in range(n)]
        assert len(self.rows) == int(np.prod([len(g) for g in self.grid])), "not a full grid"
        order = np.lexsort(tuple(self.rows[:, k] for k in reversed(range(n)))) if n else [0]
        self.values = {p: self.rows[order, n + k].reshape([len(g) for g in self.grid])
                       for k, p in enumerate(self.parameters)}

    def at(self, parameter, **args):
        """GRID: multilinear between records, the end records beyond them; args in mm / deg."""
        v = self.values[parameter]
        for k, a in enumerate(self.arguments):
            g = self.grid[k]
            t = np.clip(np.asarray(args[a], float), g[0], g[-1])
            i = np.clip(np.searchsorted(g, t, side="right") - 1, 0, max(len(g) - 2, 0))
            if len(g) == 1:
                v = v[0]
                continue
            w = (t - g[i]) / (g[i + 1] - g[i])
            v = np.moveaxis(v, 0, -1)
            v = v[..., i] * (1 - w) + v[..., i + 1] * w
        return v


def read(text: str) -> list[Block]:
    blocks, header, rows = [], None, []
    for raw in text.splitlines():
        line = raw.split("//", 1)[0].strip()
        if not line:
            continue
        if line == "#" or line.startswith("#"):
            if header:
                blocks.append(Block(header, rows))
            header, rows = None, []
            continue
        cells = line.split()
        if header is None:
            header = cells
            continue
        assert len(cells) == len(header), f"{len(cells)} cells under a header of {len(header)}: {raw!r}"
        assert all(re.fullmatch(r"-?\d+(\.\d+)?", c) for c in cells), f"not plain decimals: {raw!r}"
        rows.append([float(c) for c in cells])
    if header:
        blocks.append(Block(header, rows))
    names = [p for b in blocks for p in b.parameters]
    assert len(names) == len(set(names)), f"a parameter in two blocks: {names}"
    return blocks


def value(blocks, parameter, **args):
    """A parameter's value (mm or rad) where the axes are at ``args`` (mm / deg)."""
    for b in blocks:
        if parameter in b.parameters:
            return b.at(parameter, **args)
    return 0.0
