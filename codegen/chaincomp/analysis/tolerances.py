"""Tolerance files: how large each error source may be, and how it is distributed.

```yaml
machine: five_axis_ac          # optional: refuse another machine
description: free text         # optional
normal_bound: 3 sigma          # what 'bound' means for a normal error (default 3 sigma)
tolerances:
  EXX: {bound: 5 um, distribution: uniform}    # uniform on [-5, +5] um
  ThetaAs: {bound: 20 arcsec, distribution: normal}                    # sigma = 20/3 arcsec
  Ocx: {bound: 4 um, distribution: normal, normal_bound: 2 sigma}      # sigma = 2 um
```

A uniform error lies anywhere in [-bound, +bound]; a normal error has zero mean and
sigma = bound / k, where the bound is k sigma (``normal_bound``, per file, overridable per
error). The file's k also fixes the coverage probability p = P(|N(0,1)| <= k) (99.73 % at
3 sigma) at which the budget combines errors in its RSS and reads the Monte Carlo.
Errors not listed are taken as exactly zero deviation.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from ..errors import ChaincompError
from ..model.machine import Machine
from ..model.params import parse_value
from ..model.yamlsource import load_yaml

DISTRIBUTIONS = ("uniform", "normal")
_SIGMAS = re.compile(r"^\s*([0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)\s*(?:sigma|σ)?\s*$")
_FILE_KEYS = ("machine", "description", "normal_bound", "tolerances")
_ENTRY_KEYS = ("bound", "distribution", "normal_bound")


@dataclass(frozen=True)
class Tolerance:
    name: str           # the error symbol
    bound: float        # internal units (mm, rad)
    distribution: str   # "uniform" | "normal"
    sigmas: float       # normal: the bound is this many sigma (unused for uniform)
    line: int = 0

    @property
    def sigma(self) -> float:
        """Standard deviation, internal units."""
        if self.distribution == "uniform":
            return self.bound / math.sqrt(3.0)
        return self.bound / self.sigmas

    def quantile(self, coverage_sigmas: float) -> float:
        """Half-width of the interval that holds this error with the probability of
        +-k sigma of a normal (k = coverage_sigmas), internal units."""
        if self.distribution == "uniform":
            return self.bound * coverage(coverage_sigmas)
        return self.sigma * coverage_sigmas


@dataclass(frozen=True)
class Tolerances:
    file: str | None
    sigmas: float                  # the file's normal_bound k; also the coverage factor
    items: tuple[Tolerance, ...]   # in the machine's error order
    source: str = "file"           # "file" | "params" (bounds taken from a params file)

    @property
    def coverage(self) -> float:
        return coverage(self.sigmas)

    def by_name(self) -> dict[str, Tolerance]:
        return {t.name: t for t in self.items}


def coverage(k: float) -> float:
    """P(|N(0,1)| <= k)."""
    return math.erf(k / math.sqrt(2.0))


def _sigmas(raw, path: str, line: int, fld: str) -> float:
    if isinstance(raw, bool) or not isinstance(raw, (int, float, str)):
        raise ChaincompError(f"expected 'K sigma' (e.g. '3 sigma'), got {raw!r}", path, line, fld)
    m = _SIGMAS.match(str(raw))
    if not m:
        raise ChaincompError(f"expected 'K sigma' (e.g. '3 sigma' or '1 sigma'), got {raw!r}", path, line, fld)
    k = float(m.group(1))
    if not (math.isfinite(k) and 0.0 < k <= 10.0):
        raise ChaincompError(f"K must lie in (0, 10], got {k:g}", path, line, fld)
    return k


def load_tolerances(path: str, machine: Machine) -> Tolerances:
    """Read and validate a tolerance file; every mistake names file, line and field."""
    doc = load_yaml(path)
    if not isinstance(doc, dict):
        raise ChaincompError("expected a mapping with 'tolerances'", path, getattr(doc, "line", 1) or 1)
    for key in doc:
        if key not in _FILE_KEYS:
            raise ChaincompError(f"unknown field {key!r} (expected one of: {', '.join(_FILE_KEYS)})",
                                 path, doc.lines[key], str(key))
    if "machine" in doc and doc["machine"] != machine.name:
        raise ChaincompError(f"tolerances are for machine {doc['machine']!r}, not {machine.name!r}",
                             path, doc.lines["machine"], "machine")
    k = 3.0
    if "normal_bound" in doc:
        k = _sigmas(doc["normal_bound"], path, doc.lines["normal_bound"], "normal_bound")
    table = doc.get("tolerances")
    if not isinstance(table, dict) or not table:
        raise ChaincompError("expected a non-empty mapping of error names to {bound, distribution}",
                             path, doc.lines.get("tolerances", doc.line or 1), "tolerances")
    found: dict[str, Tolerance] = {}
    for name, entry in table.items():
        line = table.lines[name]
        fld = f"tolerances.{name}"
        try:
            sym = machine.symbol(str(name))
        except KeyError:
            raise ChaincompError(f"unknown error {name!r} for machine {machine.name!r} (errors: "
                                 f"{', '.join(s.name for s in machine.errors)})", path, line, fld) from None
        if sym.role != "error":
            raise ChaincompError(f"{name!r} is {'an' if sym.role == 'axis' else 'a'} {sym.role}: only "
                                 f"errors have tolerances", path, line, fld)
        if not isinstance(entry, dict):
            raise ChaincompError("expected a mapping {bound: VALUE UNIT, distribution: uniform|normal}",
                                 path, line, fld)
        for key in entry:
            if key not in _ENTRY_KEYS:
                raise ChaincompError(f"unknown field {key!r} (expected one of: {', '.join(_ENTRY_KEYS)})",
                                     path, entry.lines[key], f"{fld}.{key}")
        for key in ("bound", "distribution"):
            if key not in entry:
                raise ChaincompError(f"missing required field {key!r}", path, line, fld)
        bline = entry.lines["bound"]
        try:
            bound = parse_value(sym, entry["bound"])
        except ValueError as exc:
            raise ChaincompError(str(exc), path, bline, f"{fld}.bound") from None
        if bound < 0:
            raise ChaincompError(f"a bound is a half-width and cannot be negative, got {entry['bound']!r}",
                                 path, bline, f"{fld}.bound")
        dist = entry["distribution"]
        if dist not in DISTRIBUTIONS:
            raise ChaincompError(f"expected uniform or normal, got {dist!r}", path,
                                 entry.lines["distribution"], f"{fld}.distribution")
        sig = k
        if "normal_bound" in entry:
            nline = entry.lines["normal_bound"]
            if dist != "normal":
                raise ChaincompError("normal_bound applies to a normal distribution only", path, nline,
                                     f"{fld}.normal_bound")
            sig = _sigmas(entry["normal_bound"], path, nline, f"{fld}.normal_bound")
        found[sym.name] = Tolerance(sym.name, bound, dist, sig, line)
    items = tuple(found[s.name] for s in machine.errors if s.name in found)
    return Tolerances(path, k, items)


def from_params(values: dict[str, float], machine: Machine, sigmas: float = 3.0) -> Tolerances:
    """Each non-zero error value read as a bound: uniform on +-|value| (no tolerance file)."""
    items = tuple(Tolerance(s.name, abs(values[s.name]), "uniform", sigmas)
                  for s in machine.errors if values.get(s.name, 0.0) != 0.0)
    return Tolerances(None, sigmas, items, source="params")
