"""Thermal errors: error values that follow measured temperatures through first-order lags.

A thermal model adds to an error of the machine (its geometric value from the params file)

    value(t) = offset + sum_i gain_i * (lag(T_i, tau_i)(t) - T_ref)

in the error's unit; T_i is a named temperature input (a sensor, degC), tau_i its time
constant (0: no lag) and T_ref the reference temperature (ISO 1: 20 degC). The lag is the
exact response of dy/dt = (u - y)/tau to an input linear between readings, settled at the
first reading (the machine soaked at its start temperature):

    y_k = u_k - s_k tau (1 - e_k) + e_k (y_{k-1} - u_{k-1}),  e_k = exp(-dt_k/tau),
    s_k = (u_k - u_{k-1})/dt_k

``fit`` finds the offset, gains and time constants from a log of temperatures and measured
drift (variable projection: the gains by least squares at given time constants, the time
constants by Levenberg-Marquardt on their logarithms), adding the logged sensors one at a time
by how well they predict held-out stretches of the log, and writing no term the log cannot
support; ``simulate`` writes such a log from a known model."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace

import numpy as np
import yaml

from ..errors import ChaincompError
from ..escape import one_line
from ..model import csvtable, units as U
from ..model.expressions import MAX_LITERAL
from ..model.machine import Machine
from ..model.numbers import DECIMAL as _DECIMAL
from ..model.yamlsource import LineDict, LineList, describe, line_of, load_yaml, yaml11_number
from . import lsq

REFERENCE_TEMPERATURE = 20.0   # degC: ISO 1, the reference temperature of geometrical specifications
MAX_ERRORS = 64                # errors of one thermal model
MAX_TERMS = 8                  # terms of one error
MAX_SENSORS = 64               # sensors one model reads
MAX_TIME_CONSTANT = 1e6        # s (11.6 days): a machine tool's slowest structure takes hours
MAX_GAIN = 1e6                 # in the error's unit per K
TEMPERATURE_RANGE = (-100.0, 300.0)   # degC: a reading outside is a broken sensor, not a temperature
MAX_ROWS = 2_000_000           # rows of a log (a week at 3 Hz)
MAX_LOG_BYTES = 256 * 1024 * 1024
MIN_TIME_STEP = 1e-6           # s: a log's time resolution (LCM's utime)
MAX_COLUMNS = 64
SENSOR = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,31}")
_HEADER_UNIT = re.compile(r"^(.*?)\s*\[([^\]]*)\]\s*$")
TEMPERATURE_UNITS = ("degC", "°C")
SIMULATION_POINTS = 4_000_000   # the truth's time steps at most (then fewer per reading)
FOLDS = 5                      # blocked cross-validation: contiguous stretches of the log held out
CV_ITERATIONS = 6              # Levenberg-Marquardt steps per fold, from the whole log's time constants
CANDIDATES = 4                 # sensors per step cross-validated (the best of the grid the log supports; 3
                               # left T_column out, 4th by a hair, in another climate: T_coolant lagged half the log won)
COLLINEAR = 0.995              # a candidate's multiple correlation with those chosen, said to be near-collinear
MAX_RELATIVE_UNCERTAINTY = 0.5 # a term whose gain or time constant is known worse than this is not written
GOOD_RELATIVE = 0.025          # design advice: each term's standard uncertainty (within 5 % at two of them)
NOISE_DRAWS = 100              # draws of the sensors' reading noise, for the uncertainties
KEPT_BYTES = 64 * 1024 * 1024  # lagged temperatures a fit keeps
START_READINGS = 8             # a fit's first temperature: a quadratic through the first 8, 16, 32, ... readings
START_WINDOW = 900.0           # s, at most (then a fast start's curve would bias it)
START_AGREE = 3.0              # standard uncertainties a longer stretch's value may differ by (Lepski's rule)
BLOCK = 30.0                   # lag: time constants per vectorised block (exp(30) stays far from overflow)


# ----------------------------------------------------------------------------- the lag

def lag(t: np.ndarray, u: np.ndarray, tau: float, start: float | None = None) -> np.ndarray:
    """First-order lag of readings ``u`` at times ``t`` (s, increasing) with time constant
    ``tau`` (s; 0: none), exact for an input linear between readings, settled at u[0] (or at
    ``start``, the first temperature as estimated from more readings than the first)."""
    t = np.asarray(t, float)
    u = np.asarray(u, float)
    if tau == 0 or len(u) < 2:
        return u.copy()
    dt = np.diff(t)
    one_minus_e = -np.expm1(-dt / tau)
    e = 1.0 - one_minus_e
    c = u[1:] - e * u[:-1] - (np.diff(u) / dt) * tau * one_minus_e   # y_k = e_k y_{k-1} + c_k
    y = np.empty_like(u)
    y[0] = u[0] if start is None else start
    n, k = len(u), 1
    while k < n:
        y[k] = e[k - 1] * y[k - 1] + c[k - 1]
        # the readings within BLOCK time constants after t_k: y_m = P_m (y_k + sum c_j / P_j),
        # P_m = exp(-(t_m - t_k)/tau), at most exp(30) apart
        end = int(np.searchsorted(t, t[k] + BLOCK * tau, side="left"))
        if end > k + 1:
            p = np.exp(-(t[k + 1:end] - t[k]) / tau)
            y[k + 1:end] = p * (y[k] + np.cumsum(c[k:end - 1] / p))
        k = max(end, k + 1)
    return y


# ----------------------------------------------------------------------------- the model

@dataclass
class Term:
    sensor: str
    gain: float                 # the error's unit per K
    time_constant: float        # s; 0: no lag
    gain_u: float | None = None            # standard uncertainties of a fit (k = 1)
    time_constant_u: float | None = None


@dataclass
class ErrorModel:
    error: str
    unit: U.Unit
    offset: float
    terms: list[Term] = field(default_factory=list)
    offset_u: float | None = None

    def evaluate(self, t: np.ndarray, temperatures: dict[str, np.ndarray], reference: float) -> np.ndarray:
        """The error's thermal part at the log's times, in its unit."""
        value = np.full(len(t), self.offset)
        for term in self.terms:
            value = value + term.gain * (lag(t, temperatures[term.sensor], term.time_constant) - reference)
        return value


@dataclass
class ThermalModel:
    machine: str
    reference: float = REFERENCE_TEMPERATURE
    errors: dict[str, ErrorModel] = field(default_factory=dict)

    @property
    def sensors(self) -> list[str]:
        return sorted({term.sensor for e in self.errors.values() for term in e.terms})


def _number(node, key, path: str, what: str, lo: float, hi: float) -> float:
    value = node[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ChaincompError(f"expected a number ({what}), got {describe(value)}", path, line_of(node, key), key)
    try:
        value = float(value)
    except OverflowError:   # an integer of hundreds of digits
        value = math.inf if value > 0 else -math.inf
    if not (lo <= value <= hi):
        raise ChaincompError(f"{value!r} is outside [{lo:g}, {hi:g}] ({what})", path, line_of(node, key), key)
    return value


def _keys(node, allowed: tuple[str, ...], required: tuple[str, ...], path: str, where: str) -> None:
    for key in node:
        if key not in allowed:
            raise ChaincompError(f"unknown key {key!r} in {where} (expected: {', '.join(allowed)})", path,
                                 line_of(node, key), str(key))
    for key in required:
        if key not in node:
            raise ChaincompError(f"{where} needs {key!r}", path, line_of(node))


def load_model(path: str, machine: Machine | None = None) -> ThermalModel:
    """A thermal model file; every fault a ChaincompError naming the file, line and field."""
    doc = load_yaml(path)
    if not isinstance(doc, LineDict):
        raise ChaincompError(f"expected a mapping with 'machine' and 'errors', got {describe(doc)}", path, 1)
    _keys(doc, ("machine", "reference_temperature", "errors"), ("machine", "errors"), path, "a thermal model")
    name = doc["machine"]
    if not isinstance(name, str):
        raise ChaincompError(f"expected the machine's name, got {describe(name)}", path, line_of(doc, "machine"),
                             "machine")
    if machine is not None and name != machine.name:
        raise ChaincompError(f"the model is of machine {name!r}, not {machine.name!r}", path,
                             line_of(doc, "machine"), "machine")
    model = ThermalModel(name)
    if "reference_temperature" in doc:
        model.reference = _number(doc, "reference_temperature", path, "degC", *TEMPERATURE_RANGE)
    errors = doc["errors"]
    if not isinstance(errors, LineDict) or not errors:
        raise ChaincompError("expected a mapping of error names to their models, got "
                             f"{describe(errors) if errors != {} else 'an empty mapping'}", path,
                             line_of(doc, "errors"), "errors")
    if len(errors) > MAX_ERRORS:
        raise ChaincompError(f"{len(errors)} errors: a thermal model holds at most {MAX_ERRORS}", path,
                             line_of(doc, "errors"), "errors")
    for err, node in errors.items():
        line = line_of(errors, err)
        if machine is not None:
            known = {s.name: s for s in machine.errors}
            if err not in known:
                raise ChaincompError(f"{err!r} is not an error of {machine.name}", path, line, str(err))
        if not isinstance(node, LineDict):
            raise ChaincompError(f"expected a mapping with unit, offset and terms, got {describe(node)}", path,
                                 line, str(err))
        _keys(node, ("unit", "offset", "terms"), ("unit", "terms"), path, f"error {err}")
        unit = U.UNITS.get(node["unit"]) if isinstance(node["unit"], str) else None
        if unit is None:
            raise ChaincompError(f"expected a unit (um, arcsec, ppm, ...), got {describe(node['unit'])}",
                                 path, line_of(node, "unit"), "unit")
        if machine is not None and known[err].unit.kind != unit.kind:
            raise ChaincompError(f"{err} is {'an' if known[err].unit.kind == 'angle' else 'a'} {known[err].unit.kind} "
                                 f"in {machine.name}, not {'an' if unit.kind == 'angle' else 'a'} {unit.kind}",
                                 path, line_of(node, "unit"), "unit")
        limit = MAX_LITERAL / unit.to_internal
        em = ErrorModel(str(err), unit, _number(node, "offset", path, unit.name, -limit, limit)
                        if "offset" in node else 0.0)
        terms = node["terms"]
        if not isinstance(terms, LineList) or not 1 <= len(terms) <= MAX_TERMS:
            raise ChaincompError(f"expected a list of 1 to {MAX_TERMS} terms, got {describe(terms)}", path,
                                 line_of(node, "terms"), "terms")
        seen: dict[str, int] = {}
        for i, term in enumerate(terms):
            tline = line_of(terms, i)
            if not isinstance(term, LineDict):
                raise ChaincompError(f"expected a term {{sensor, gain, time_constant}}, got {describe(term)}", path,
                                     tline, "terms")
            _keys(term, ("sensor", "gain", "time_constant"), ("sensor", "gain"), path, "a term")
            sensor = term["sensor"]
            if not isinstance(sensor, str) or not SENSOR.fullmatch(sensor):
                raise ChaincompError(f"expected a sensor name (a letter or _, then letters, digits or _, at most 32), "
                                     f"got {describe(sensor)}", path, line_of(term, "sensor"), "sensor")
            gain = _number(term, "gain", path, f"{unit.name}/K", -MAX_GAIN, MAX_GAIN)
            tau = _number(term, "time_constant", path, "s, 0 for no lag", 0.0, MAX_TIME_CONSTANT) \
                if "time_constant" in term else 0.0
            key = f"{sensor}@{tau + 0.0!r}"   # (-0.0 is 0)
            if key in seen:
                raise ChaincompError(f"a second term of sensor {sensor} with time constant {tau:g} s (the first on "
                                     f"line {seen[key]}): add their gains", path, tline, "terms")
            seen[key] = tline
            em.terms.append(Term(sensor, gain, tau))
        model.errors[em.error] = em
        if len(model.sensors) > MAX_SENSORS:
            raise ChaincompError(f"more than {MAX_SENSORS} sensors in the model", path, line, str(err))
    return model


def _g(v: float) -> str:
    """6 significant digits, spelled so that YAML 1.1 reads a number back (1.0e+06, not 1e+06)."""
    text = f"{v:.6g}"
    return "0" if text in ("-0", "0") else yaml11_number(text) or text


def _name(sensor: str) -> str:
    """A sensor's name as YAML reads it back: quoted where it would be a bool or null (on, No, null)."""
    return sensor if yaml.safe_load(sensor) == sensor else f"'{sensor}'"


def model_text(model: ThermalModel, header: list[str]) -> str:
    """The model as a file ``load_model`` reads (uncertainties as comments)."""
    lines = [f"# {one_line(h)}" for h in header]
    lines += [f"machine: {model.machine}",
              f"reference_temperature: {_g(model.reference)}   # degC: each term is gain * (lagged temperature - this)",
              "errors:"]
    for em in model.errors.values():
        u = f"   # ± {_g(em.offset_u)} (standard uncertainty)" if em.offset_u is not None else ""
        lines += [f"  {em.error}:",
                  f"    unit: {em.unit.name}   # of the offset, and per K of each gain",
                  f"    offset: {_g(em.offset)}{u}",
                  "    terms:   # gain in " + em.unit.name + "/K, time_constant in s (0: no lag)"]
        for term in em.terms:
            u = ""
            if term.gain_u is not None:
                u = f"   # ± {_g(term.gain_u)} {em.unit.name}/K, ± {_g(term.time_constant_u or 0.0)} s"
            lines.append(f"      - {{sensor: {_name(term.sensor)}, gain: {_g(term.gain)}, "
                         f"time_constant: {_g(term.time_constant)}}}{u}")
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------- the log

@dataclass
class Log:
    path: str
    t: np.ndarray                         # s
    temperatures: dict[str, np.ndarray]   # degC
    drift: dict[str, np.ndarray]          # error name -> values in drift_units[name]
    drift_units: dict[str, U.Unit]
    columns: dict[str, str]               # sensor or error -> its header cell


def read_log(path: str, machine: Machine, rename: dict[str, str] | None = None, require_drift: bool = True) -> Log:
    """A CSV log: a 'time [s]' column, temperature columns ('NAME [degC]') and drift columns
    named by errors of the machine ('EZZ [um]'; ``rename`` maps other names to errors)."""
    rename = dict(rename or {})
    table = csvtable.read(path, max_rows=MAX_ROWS, max_bytes=MAX_LOG_BYTES,
                          example="time [s],T_spindle [degC],EZZ [um]")
    header, hline = table.header, table.line
    if len(header) > MAX_COLUMNS:
        raise ChaincompError(f"{len(header)} columns: a log holds at most {MAX_COLUMNS}", path, hline)
    errors = {s.name: s for s in machine.errors}
    time_col, kinds, names = None, [], []   # per column: time, temperature or drift; sensor or error
    for k, cell in enumerate(header):
        m = _HEADER_UNIT.match(cell.strip())
        name, unit = (m.group(1).strip(), m.group(2).strip()) if m else (cell.strip(), None)
        if unit is None:
            raise ChaincompError(f"column {k + 1} ({cell.strip()!r}) has no unit: write it in brackets, e.g. "
                                 "'time [s]', 'T_spindle [degC]', 'EZZ [um]'", path, hline, cell.strip())
        if name.lower() == "time":
            if unit != "s":
                raise ChaincompError(f"time in {unit!r}: write it in seconds ('time [s]')", path, hline, cell.strip())
            if time_col is not None:
                raise ChaincompError(f"two time columns ({time_col + 1} and {k + 1})", path, hline, cell.strip())
            time_col = k
            kinds.append("time")
            names.append("time")
            continue
        if unit in TEMPERATURE_UNITS:
            if name in rename:
                raise ChaincompError(f"--drift {name}={rename[name]}: column {name} is a temperature, not a drift",
                                     path, hline, cell.strip())
            if not SENSOR.fullmatch(name):
                raise ChaincompError(f"sensor name {name!r}: a letter or _, then letters, digits or _ (at most 32)",
                                     path, hline, cell.strip())
            kinds.append("temperature")
            names.append(name)
            continue
        try:
            u = U.unit(unit)
        except KeyError as exc:
            raise ChaincompError(f"{exc.args[0]}; or a temperature in {' or '.join(TEMPERATURE_UNITS)}", path,
                                 hline, cell.strip()) from None
        mapped = name in rename
        error = rename.pop(name, name)
        if error not in errors:
            hint = (f"--drift {name}={error} names no error of it" if mapped else "name the column by the error it "
                    f"measures, e.g. EZZ, or map it with --drift {name}=ERROR")
            raise ChaincompError(f"drift column {name!r} is not an error of {machine.name} ({hint})", path, hline,
                                 cell.strip())
        if u.kind != errors[error].unit.kind:
            raise ChaincompError(f"{error} is {'an' if errors[error].unit.kind == 'angle' else 'a'} "
                                 f"{errors[error].unit.kind} but the column is in {u.name}", path, hline, cell.strip())
        kinds.append("drift")
        names.append(error)
    if rename:
        raise ChaincompError(f"--drift: no column {', '.join(sorted(rename))} in the header", path, hline)
    if time_col is None:
        raise ChaincompError(f"no 'time [s]' column (header: {', '.join(header)})", path, hline)
    for kind in ("temperature", "drift") if require_drift else ("temperature",):
        if kind not in kinds:
            raise ChaincompError(f"no {kind} column ({'NAME [degC]' if kind == 'temperature' else 'ERROR [um]'}; "
                                 f"header: {', '.join(header)})", path, hline)
    seen: dict[str, int] = {}
    for k, name in enumerate(names):
        if name in seen:
            raise ChaincompError(f"two columns of {name} ({seen[name] + 1} and {k + 1})", path, hline, header[k].strip())
        seen[name] = k
    data = np.empty((min(table.lines_left, MAX_ROWS), len(header)))
    n = 0
    previous = None
    for row in table.rows:
        line = row.line
        values = []
        for k, cell in enumerate(row.cells):
            v = table.number(row, k)
            if not abs(v) <= MAX_LITERAL:
                raise ChaincompError(f"{cell!r} is larger than {MAX_LITERAL:g} in magnitude", path, line, header[k])
            if kinds[k] == "temperature" and not TEMPERATURE_RANGE[0] <= v <= TEMPERATURE_RANGE[1]:
                raise ChaincompError(f"{v:g} degC is outside [{TEMPERATURE_RANGE[0]:g}, {TEMPERATURE_RANGE[1]:g}] "
                                     "degC: a broken sensor?", path, line, header[k].strip())
            values.append(v)
        now = values[time_col]
        if previous is not None and not now >= previous + MIN_TIME_STEP:
            raise ChaincompError(f"time {now:g} s does not follow {previous:g} s by at least {MIN_TIME_STEP:g} s "
                                 "(times must increase)", path, line, header[time_col].strip())
        previous = now
        data[n] = values
        n += 1
    data = data[:n]
    if len(data) < 10:
        raise ChaincompError(f"{len(data)} rows: a fit needs at least 10", path, hline)
    units = {}
    for k, cell in enumerate(header):
        if kinds[k] == "drift":
            units[names[k]] = U.unit(_HEADER_UNIT.match(cell.strip()).group(2).strip())
    return Log(path, data[:, time_col],
               {n: data[:, k] for k, n in enumerate(names) if kinds[k] == "temperature"},
               {n: data[:, k] for k, n in enumerate(names) if kinds[k] == "drift"}, units,
               {n: header[k].strip() for k, n in enumerate(names)})


# ----------------------------------------------------------------------------- the fit

@dataclass
class Fit:
    model: ErrorModel
    rms_before: float      # of the drift about its mean, the error's unit
    rms_after: float
    max_before: float
    max_after: float
    steps: list[tuple[str, float, float]]   # the sensors in the order chosen: RMS left, held-out RMS after each
    span: float = 0.0                        # s, the log's
    notes: list[str] = field(default_factory=list)   # collinear candidates, equal sets, terms dropped
    cv_rms: float = 0.0                      # held-out RMS of the model chosen (blocked cross-validation)


class _Kept(dict):
    """A log's temperatures with the lags a fit computed kept, newest KEPT_BYTES of them: the fit
    asks for the same ones many times (each candidate's Jacobian changes one column). Each
    sensor's lags start at its first temperature estimated from its first readings
    (start_readings): the first reading's own noise would stay in a long lag for hours, and
    T_column's time constant came out 1.5 times as scattered as the Cramer-Rao bound allows
    (tools/bench_thermal)."""

    def __init__(self, t: np.ndarray, temps: dict[str, np.ndarray]):
        super().__init__(temps)
        self.t = t
        self.kept: dict[tuple[str, float], np.ndarray] = {}
        self.start_n = {s: start_readings(t, u) for s, u in temps.items()}
        self.start = {s: _start(t, u, self.start_n[s])[0] for s, u in temps.items()}

    def lagged(self, sensor: str, tau: float) -> np.ndarray:
        y = self.kept.get((sensor, tau))
        if y is None:
            y = lag(self.t, self[sensor], tau, self.start[sensor])
            while self.kept and (len(self.kept) + 1) * y.nbytes > KEPT_BYTES:
                del self.kept[next(iter(self.kept))]
            self.kept[sensor, tau] = y
        return y


def _design(t, temps, chosen, taus, reference) -> np.ndarray:
    cols = [np.ones(len(t))] + [temps.lagged(s, tau) - reference for s, tau in zip(chosen, taus)]
    return np.stack(cols, axis=1)


def _solve(a: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, float]:
    coef = lsq.solve(a, d)
    # einsum, not BLAS: a multithreaded BLAS on a busy machine makes these products 100 times slower
    r = d - np.einsum("ij,j->i", a, coef)
    return coef, float(np.einsum("i,i->", r, r))


def _refine(t, temps, d, chosen, taus, reference, lo, hi, iterations: int = 40, rows=None):
    """Levenberg-Marquardt on the logarithms of the positive time constants (the gains solved at
    each step, on ``rows`` of the log only when given): the time constants and the residual sum
    of squares. The lags run over the whole log: the temperatures are known everywhere."""
    rows = slice(None) if rows is None else rows
    d = d[rows]

    def design(ts):
        return _design(t, temps, chosen, ts, reference)[rows]

    free = [i for i, tau in enumerate(taus) if tau > 0]
    taus = list(taus)

    def rss(ts):
        return _solve(design(ts), d)[1]

    if not free:
        return taus, rss(taus)
    h = 1e-5

    def linearise(ts):   # the residual (gains solved), its derivatives in log tau by forward differences
        a = design(ts)
        coef, value = _solve(a, d)
        r = d - np.einsum("ij,j->i", a, coef)
        jac = np.empty((len(d), len(free)))
        for j, i in enumerate(free):
            up = list(ts)
            up[i] = ts[i] * math.exp(h)
            a_up = design(up)
            c_up, _ = _solve(a_up, d)
            jac[:, j] = ((d - np.einsum("ij,j->i", a_up, c_up)) - r) / h
        return r, jac, value

    def update(ts, step):  # a step in log tau, at most a factor e^2, within [lo, hi]
        trial = list(ts)
        for j, i in enumerate(free):
            trial[i] = float(np.clip(ts[i] * math.exp(float(np.clip(step[j], -2, 2))), lo, hi))
        return trial

    return lsq.levenberg_marquardt(linearise, rss, update, taus, iterations)


def _held_out(t, temps, d, chosen, taus, reference, lo, hi, folds: int = FOLDS) -> np.ndarray:
    """Blocked cross-validation: the log cut into ``folds`` contiguous stretches of time; each in
    turn is held out, the model fitted to the others (gains solved, time constants refined from
    the whole log's) and the held-out stretch's drift predicted. Per stretch, the mean squared
    error of that prediction."""
    n = len(d)
    edges = np.linspace(0, n, folds + 1).astype(int)
    out = np.empty(folds)
    for k in range(folds):
        train = np.r_[0:edges[k], edges[k + 1]:n]
        ktaus, _ = _refine(t, temps, d, chosen, taus, reference, lo, hi, iterations=CV_ITERATIONS, rows=train)
        a = _design(t, temps, chosen, ktaus, reference)
        coef, _ = _solve(a[train], d[train])
        r = d[edges[k]:edges[k + 1]] - a[edges[k]:edges[k + 1]] @ coef
        out[k] = float(np.mean(r ** 2))
    return out


def _paired_se(a: np.ndarray, b: np.ndarray) -> float:
    """Standard error of the mean of the per-stretch differences of two held-out scores."""
    return float(np.std(a - b, ddof=1) / math.sqrt(len(a)))


def _collinearity(a: np.ndarray, j: int) -> float:
    """Multiple correlation of column ``j`` of a design (after the offset) with its other columns:
    1 when the others reproduce it exactly (the log cannot tell its gain from theirs)."""
    x = a[:, j] - a[:, j].mean()
    others = np.delete(a, j, axis=1)
    if others.shape[1] < 2 or not np.any(x):
        return 0.0
    coef = lsq.solve(others, a[:, j])
    r = a[:, j] - others @ coef
    return float(math.sqrt(max(0.0, 1.0 - (r @ r) / (x @ x))))


def reading_noise(u: np.ndarray) -> float:
    """A sensor's reading noise (standard deviation, K) from its second differences, which a
    temperature's own curvature between readings hardly moves (the median: robust to a step)."""
    d2 = np.diff(np.asarray(u, float), 2)
    if len(d2) < 3:
        return 0.0
    return 1.4826 * float(np.median(np.abs(d2 - np.median(d2)))) / math.sqrt(6)


def start_readings(t: np.ndarray, u: np.ndarray) -> int:
    """How many of the first readings a fit estimates a sensor's first temperature from (the
    lags start settled there): the longest of 8, 16, 32, ... readings within START_WINDOW s
    whose quadratic's value at the first time agrees with every shorter one's within
    START_AGREE times that one's standard uncertainty (Lepski's rule: as many readings as the
    start's curve allows; at twice, noise alone stopped it early on 7 of 50 soaked starts, and
    T_spindle's start was then worse than its first reading). 1: the first reading alone (a
    sensor without noise, or too few readings)."""
    sigma = reading_noise(u)
    if not sigma > 0:
        return 1
    kept: list[tuple[float, float]] = []   # (value, its standard uncertainty) of each accepted length
    n, m = 1, START_READINGS
    while m <= len(u) and t[m - 1] - t[0] <= START_WINDOW:
        value, weights = _start(t, u, m)
        sd = sigma * math.sqrt(float(weights @ weights))
        if any(abs(value - v) > START_AGREE * s for v, s in kept):
            break
        kept.append((value, sd))
        n, m = m, 2 * m
    return n


def _start(t: np.ndarray, u: np.ndarray, n: int) -> tuple[float, np.ndarray]:
    """The value at t[0] of the quadratic in time through the first ``n`` readings, and the
    weights it gives them (linear: the same weights carry the readings' noise)."""
    if n < 3:
        return float(u[0]), np.array([1.0])
    x = (t[:n] - t[0]) / (t[n - 1] - t[0])
    weights = np.linalg.pinv(np.vander(x, 3))[-1]
    return float(weights @ u[:n]), weights


def _uncertainties(t, temps, d, chosen, taus, coef, reference, draws: int = NOISE_DRAWS) -> np.ndarray:
    """Standard uncertainties of (offset, gains, time constants) from the Jacobian of the full
    model at the solution: white noise on the drift readings, plus each chosen sensor's reading
    noise carried through its lag (NOISE_DRAWS draws of it, linearised: the first temperature's
    noise stays in a long lag for hours, as large as the drift's noise averaged over them)."""
    a = _design(t, temps, chosen, taus, reference)
    r = d - a @ coef
    cols = [a[:, 0]] + [a[:, 1 + i] for i in range(len(chosen))]
    for i, (s, tau) in enumerate(zip(chosen, taus)):
        if tau > 0:
            dtau = tau * 1e-6
            cols.append(coef[1 + i] * (lag(t, temps[s], tau + dtau, temps.start[s]) -
                                       lag(t, temps[s], tau - dtau, temps.start[s])) / (2 * dtau))
    jac = np.stack(cols, axis=1)
    s2 = lsq.residual_variance(r, max(len(d) - jac.shape[1], 1))
    try:
        inverse = lsq.normal_inverse(jac)
    except np.linalg.LinAlgError:
        return np.full(jac.shape[1], math.inf)
    cov = s2 * inverse
    sigma = [reading_noise(temps[s]) for s in chosen]
    if chosen and any(sigma) and draws:
        rng = np.random.default_rng(0)   # the same uncertainties on every run
        project = inverse @ jac.T
        shifts = np.array([project @ sum(coef[1 + i] * _noise_lagged(t, rng.normal(0.0, sigma[i], len(t)), taus[i],
                                                                     temps.start_n[chosen[i]])
                                         for i in range(len(chosen))) for _ in range(draws)])
        cov = cov + shifts.T @ shifts / draws
    return np.sqrt(np.maximum(np.diag(cov), 0.0))


def _noise_lagged(t: np.ndarray, noise: np.ndarray, tau: float, start_n: int) -> np.ndarray:
    """Readings' noise through a lag as the fit's lags carry it: starting at its first
    ``start_n`` readings' estimate of the first temperature."""
    return lag(t, noise, tau, _start(t, noise, start_n)[0])


def _model(t, temps, d, error, unit, chosen, taus, reference,
           draws: int = NOISE_DRAWS) -> tuple[ErrorModel, np.ndarray]:
    """The error model at the given sensors and time constants (gains solved), with its
    uncertainties, and its residual."""
    a = _design(t, temps, chosen, taus, reference)
    coef, _ = _solve(a, d)
    u = _uncertainties(t, temps, d, chosen, taus, coef, reference, draws)
    tau_u = iter(u[1 + len(chosen):])
    em = ErrorModel(error, unit, float(coef[0]), offset_u=float(u[0]))
    for i, (s, tau) in enumerate(zip(chosen, taus)):
        em.terms.append(Term(s, float(coef[1 + i]), float(tau), float(u[1 + i]),
                             float(next(tau_u)) if tau > 0 else 0.0))
    return em, d - a @ coef


def unsupported(term: Term, span: float, max_relative: float) -> str | None:
    """Why the log cannot support a fitted term, or None: its gain or time constant known to
    worse than ``max_relative`` of its value (standard uncertainty), or a time constant longer
    than the log."""
    if not term.gain_u <= max_relative * abs(term.gain):
        return f"gain {term.gain:.4g} ± {term.gain_u:.2g}"
    if term.time_constant > span:
        return f"time constant {term.time_constant:.4g} s is longer than the log ({span:.4g} s)"
    if term.time_constant > 0 and not term.time_constant_u <= max_relative * term.time_constant:
        return f"time constant {term.time_constant:.4g} ± {term.time_constant_u:.2g} s"
    return None


def identifiability(term: Term, span: float) -> str:
    """How well the log pins down a term's time constant, in words."""
    if term.time_constant == 0:
        return "no lag"
    rel = term.time_constant_u / term.time_constant
    cover = f"{span / term.time_constant:.3g} time constants in the log"
    if rel <= 0.05 and term.time_constant <= span / 3:
        return f"identified (± {100 * rel:.2g} %, {cover})"
    if rel <= 0.2:
        return f"weakly identified (± {100 * rel:.2g} %, {cover})"
    return f"poorly identified (± {100 * rel:.2g} %, {cover})"


def fit(log: Log, error: str, sensors: list[str], reference: float = REFERENCE_TEMPERATURE,
        max_sensors: int = 3, min_improvement: float = 0.1, lags: bool = True, progress=None,
        max_relative: float = MAX_RELATIVE_UNCERTAINTY) -> Fit:
    """The thermal model of ``error`` from the log. Sensors are added one at a time (each
    candidate's time constants refined together with those chosen) while the one that predicts
    held-out stretches of the log best (blocked cross-validation) improves that prediction by
    more than its standard error, lowers the RMS residual by ``min_improvement`` (relative) and
    passes Schwarz's criterion. Terms the log cannot support (``unsupported``) are then taken
    out, one at a time, worst first: a time constant by writing the term without a lag when that
    fits as well, else the whole term."""
    t, d = log.t, log.drift[error]
    temps = _Kept(t, log.temperatures)
    unit = log.drift_units[error]
    n = len(d)
    span = float(t[-1] - t[0])
    lo = max(float(np.median(np.diff(t))), 1e-3)
    hi = min(10 * span, MAX_TIME_CONSTANT)
    grid = [0.0] + (list(np.geomspace(lo, hi, 24)) if lags and hi > lo else [])
    rms0 = float(np.sqrt(np.mean((d - d.mean()) ** 2)))
    if not rms0 > 0:
        raise ChaincompError(f"{error}: the drift is constant ({float(d[0]):g} {unit.name}): nothing to fit",
                             log.path)
    say = progress or (lambda text: None)
    notes: list[str] = []

    def note(text: str) -> None:   # for the report (progress tells the steps as they happen)
        notes.append(text)

    # a sensor that does not vary (below any sensor's resolution) explains nothing but rounding
    sensors = [s for s in dict.fromkeys(sensors) if np.ptp(temps[s]) > 1e-6]
    chosen: list[str] = []
    taus: list[float] = []
    rss = float(np.sum((d - d.mean()) ** 2))
    score = _held_out(t, temps, d, [], [], reference, lo, hi)
    steps = []
    while len(chosen) < min(max_sensors, len(sensors)) and rss > 0:
        base = _design(t, temps, chosen, taus, reference)
        ranked = []
        for s in sensors:   # each sensor at its best time constant of the grid, the others held
            if s in chosen:
                continue
            best = min((_solve(np.column_stack([base, temps.lagged(s, tau) - reference]), d)[1], tau) for tau in grid)
            ranked.append((best[0], s, best[1]))
        trials = []
        refused = []
        for _, s, tau in sorted(ranked):
            if len(trials) == CANDIDATES:
                break
            new_taus, new_rss = _refine(t, temps, d, chosen + [s], taus + [tau], reference, lo, hi)
            # a candidate that would make a term the log cannot support is not one (it would be
            # dropped, and a slow ramp beyond the log would crowd out a sensor it can support);
            # the drift's noise alone here, the sensors' comes in the final uncertainties
            trial, _ = _model(t, temps, d, error, unit, chosen + [s], new_taus, reference, draws=0)
            why = next((f"{term.sensor}: {w}" for term in trial.terms if (w := unsupported(term, span, max_relative))),
                       None)
            if why:
                refused.append(f"{s} ({why})")
                # the log's first choice, and one that would lower the residual as a sensor taken
                # must: the report says why it is not taken (not of every sensor that explains noise)
                if not trials and _lowers(rss, new_rss, n, min_improvement):
                    note(f"{s} not taken, the log cannot support it ({why})")
                continue
            a = _design(t, temps, chosen + [s], new_taus, reference)
            trials.append({"sensor": s, "taus": new_taus, "rss": new_rss, "collinear": _collinearity(a, a.shape[1] - 1),
                           "score": _held_out(t, temps, d, chosen + [s], new_taus, reference, lo, hi)})
        if refused:
            say(f"{error}: not candidates, the log could not support them: {'; '.join(refused)}")
        if not trials:
            break
        trials.sort(key=lambda c: c["score"].mean())
        best = trials[0]
        found = []   # said of the step if it is taken
        # the same held-out prediction within the score's standard error: said. Every candidate
        # has as many terms as the others, its time constants inside the log's span, and the log
        # supports it: none is simpler, and the best score is taken
        se_best = float(np.std(best["score"], ddof=1) / math.sqrt(len(best["score"])))
        equal = [c for c in trials[1:] if c["score"].mean() - best["score"].mean() <= se_best]
        if equal:
            found.append(f"{', '.join(c['sensor'] for c in [best] + equal)} predict held-out stretches equally "
                         f"well (within the score's standard error): taking {best['sensor']}, the best of them")
        if best["collinear"] > COLLINEAR:
            found.append(f"{best['sensor']} lagged {best['taus'][-1]:.4g} s is near-collinear with "
                         f"{', '.join(chosen) or 'the offset'} (multiple correlation {best['collinear']:.4f}): the "
                         "log hardly tells their gains apart")
        gain = float(np.mean(score - best["score"]))
        se = _paired_se(score, best["score"])
        new_rss = best["rss"]
        # held-out: better by more than its standard error; in-sample: Schwarz's and min_improvement
        if not gain > se or not _lowers(rss, new_rss, n, min_improvement):
            if chosen and gain > 0:
                say(f"{error}: {best['sensor']} not taken: held-out RMS {math.sqrt(score.mean()):.4g} -> "
                    f"{math.sqrt(best['score'].mean()):.4g}, within the standard error or below --min-improvement")
            break
        chosen, taus, rss, score = chosen + [best["sensor"]], best["taus"], new_rss, best["score"]
        notes += found
        steps.append((best["sensor"], math.sqrt(rss / n), math.sqrt(score.mean())))
        say(f"{error}: + {best['sensor']} (time constant {taus[-1]:.4g} s): RMS left {math.sqrt(rss / n):.4g}, "
            f"held-out {math.sqrt(score.mean()):.4g}")
    while True:   # no term the log cannot support
        em, residual = _model(t, temps, d, error, unit, chosen, taus, reference)
        bad = [(i, why) for i, term in enumerate(em.terms) if (why := unsupported(term, span, max_relative))]
        if not bad:
            break
        i, why = max(bad, key=lambda b: _relative(em.terms[b[0]]))
        term = em.terms[i]
        if taus[i] > 0 and "gain" not in why:   # the same sensor without a lag, if that fits as well
            no_lag = taus[:i] + [0.0] + taus[i + 1:]
            trial, trial_rss = _refine(t, temps, d, chosen, no_lag, reference, lo, hi)
            trial_em, _ = _model(t, temps, d, error, unit, chosen, trial, reference)
            if n * math.log(trial_rss / max(float(residual @ residual), 1e-300)) <= math.log(n) and \
                    unsupported(trial_em.terms[i], span, max_relative) is None:
                note(f"{term.sensor}: {why}: the log cannot support it; written without a lag (it fits as well)")
                taus = trial
                continue
        note(f"{term.sensor}: {why}: the log cannot support it; term dropped")
        chosen, taus = chosen[:i] + chosen[i + 1:], taus[:i] + taus[i + 1:]
        if chosen:
            taus, _ = _refine(t, temps, d, chosen, taus, reference, lo, hi)
    for term in em.terms:   # what a model file can hold (and the daemon takes)
        if not abs(term.gain) <= MAX_GAIN:
            raise ChaincompError(f"{error}: the fitted gain on {term.sensor} is {term.gain:.3g} {unit.name}/K, beyond "
                                 f"{MAX_GAIN:g}: the sensor hardly varies over the log", log.path)
    cv = _held_out(t, temps, d, chosen, taus, reference, lo, hi) if chosen else score
    return Fit(em, rms0, float(np.sqrt(np.mean(residual ** 2))), float(np.max(np.abs(d - d.mean()))),
               float(np.max(np.abs(residual))), steps, span, notes, math.sqrt(float(cv.mean())))


def _lowers(rss: float, new_rss: float, n: int, min_improvement: float) -> bool:
    """Whether a sensor lowers the residual as one taken must: by Schwarz's criterion (a gain and
    a time constant must lower n ln(RSS) by more than 2 ln(n)) and by ``min_improvement`` of
    the RMS."""
    return n * math.log(rss / max(new_rss, 1e-300 * rss)) > 2 * math.log(n) and \
        math.sqrt(new_rss) <= (1 - min_improvement) * math.sqrt(rss)


def _relative(term: Term) -> float:
    """A term's worst relative standard uncertainty (gain or time constant)."""
    rel = term.gain_u / abs(term.gain) if term.gain else math.inf
    if term.time_constant > 0:
        rel = max(rel, term.time_constant_u / term.time_constant)
    return rel


def information_needed(term: Term) -> float:
    """How many times its log's information a term needs to be known to GOOD_RELATIVE: a
    variance falls as one over the number of readings and as the drift's noise squared."""
    return (_relative(term) / GOOD_RELATIVE) ** 2


def advised_noise(f: Fit) -> float:
    """The drift readings' noise (standard deviation, the error's unit) at which the same log
    would pin every term down to GOOD_RELATIVE: this fit's residual RMS scaled by the worst
    term's information_needed (the residual itself when the log already does)."""
    need = max([information_needed(term) for term in f.model.terms], default=1.0)
    return f.rms_after / math.sqrt(max(need, 1.0))


def advice(f: Fit) -> list[str]:
    """What log would pin down what this fit leaves uncertain: from each term's relative
    uncertainties and time constant against the log's span. Within 5 % at two standard
    uncertainties (95 % of logs) asks for GOOD_RELATIVE; uncertainties shrink as one over the
    square root of the number of readings, and in proportion to the drift's noise
    (tools/bench_thermal checks the noise it names)."""
    out = []
    u = f.model.unit.name
    for term in f.model.terms:
        rel = _relative(term)
        need = information_needed(term)
        if term.time_constant > f.span / 3:
            out.append(f"{term.sensor}'s time constant ({term.time_constant:.4g} s) is more than a third of the log "
                       f"({f.span:.4g} s): a log of at least 5 time constants ({5 * term.time_constant / 3600:.3g} h), "
                       "e.g. a cool-down that long after a step in spindle duty, would pin it down.")
        elif need > 1:
            out.append(f"{term.sensor} is known to ± {100 * rel:.2g} % (one standard uncertainty): within 5 % at two "
                       f"(± {100 * GOOD_RELATIVE:.2g} %) needs {need:.2g} times this log's information: drift "
                       f"readings with at most {f.rms_after / math.sqrt(need):.2g} {u} of noise (this fit left "
                       f"{f.rms_after:.2g} {u} RMS), or {need:.2g} times as many readings over the same cycle.")
    if any("cannot support" in n for n in f.notes):
        out.append("A term the log cannot support was left out: a longer cool-down (5 times the slowest time "
                   "constant the machine may have), or a step in spindle duty that moves its sensor apart from the "
                   "others, would show whether it is there.")
    if any("near-collinear" in n or "equally well" in n for n in f.notes):
        out.append("Sensors that move together are told apart by a log in which they do not: another day's "
                   "hall climate, or a spindle duty step followed by a long stop.")
    return out or [f"The log pins down every term to ± {100 * GOOD_RELATIVE:.2g} % or better (within 5 % at two "
                   "standard uncertainties)."]



# ----------------------------------------------------------------------------- simulation

@dataclass
class Sensor:
    """A simulated sensor: the hall's temperature through a lag, plus ``rise`` K at full spindle
    duty reached through another, plus a chiller's triangular swing (coolant)."""
    name: str
    rise: float                 # K at full spindle duty, once settled
    time_constant: float        # s, of the rise
    ambient_lag: float = 0.0    # s, of the hall's temperature
    ambient: float = 1.0        # how much of the hall's swing it follows (a cooled spindle: little)
    swing: float = 0.0          # K, peak to peak
    swing_period: float = 1.0   # s


DEFAULT_SENSORS = [Sensor("T_spindle", 15.0, 1200.0, 600.0, 0.2), Sensor("T_column", 2.0, 5400.0, 2400.0),
                   Sensor("T_bed", 0.5, 14400.0, 7200.0), Sensor("T_coolant", 1.0, 600.0, 0.0, 0.3, 0.8, 1500.0),
                   Sensor("T_ambient", 0.0, 0.0, 0.0)]
# spindle duty (0..1) and how long it is held, s
CYCLES = {
    "warmup": [(0.0, 900), (1.0, 10800), (0.4, 5400), (0.0, 9000)],
    "varied": [(0.7, 7200), (0.0, 3600), (1.0, 5400), (0.2, 3600), (0.0, 7200)],
}
# the hall: 20 degC and a sum of slow swings (K amplitude, s period), phases drawn from the seed
# (simulate-thermal --hall sets others)
HALL = (20.0, [(1.0, 86400.0), (0.6, 14400.0), (0.4, 5400.0), (0.2, 2700.0)])


def parse_cycle(text: str) -> list[tuple[float, float]]:
    """'1:3600,0:1800' (duty:seconds, ...) or a named cycle."""
    if text in CYCLES:
        return CYCLES[text]
    out = []
    expected = f"{' or '.join(CYCLES)} or DUTY:SECONDS,..., e.g. 1:3600,0:1800"
    for part, (duty, seconds) in _pairs(text, "--cycle", expected):
        if not 0 <= duty <= 1 or not 0 < seconds <= 1e6:
            raise ChaincompError(f"--cycle: {part!r}: the duty is from 0 to 1, the time from 0 to 1e6 s")
        out.append((duty, seconds))
    return out


def _pairs(text: str, option: str, expected: str) -> list[tuple[str, tuple[float, float]]]:
    """The items of 'A:B,C:D' as (the item as written, (A, B)), each two plain decimals."""
    out = []
    for part in text.split(","):
        bits = part.split(":")
        if len(bits) != 2 or not all(_DECIMAL.fullmatch(b.strip()) for b in bits):
            raise ChaincompError(f"{option}: expected {expected}, got {part!r}")
        out.append((part, (float(bits[0]), float(bits[1]))))
    return out


def parse_hall(text: str) -> list[tuple[float, float]]:
    """The hall's swings: 'default' or AMPLITUDE:PERIOD,... (K, s), e.g. 2:86400,1:7200."""
    if text == "default":
        return HALL[1]
    out = []
    expected = "default or AMPLITUDE:PERIOD,... (K, s), e.g. 2:86400,1:7200"
    for part, (amplitude, period) in _pairs(text, "--hall", expected):
        if not 0 <= amplitude <= 20 or not 60 <= period <= 1e7:
            raise ChaincompError(f"--hall: {part!r}: the amplitude is from 0 to 20 K, the period from 60 to 1e7 s")
        out.append((amplitude, period))
    return out


def sensors_with_lags(scale: float) -> list[Sensor]:
    """The simulated sensors with each of their own time constants times ``scale`` (another
    machine's structure: the true model's lags are not scaled)."""
    return [replace(s, time_constant=s.time_constant * scale, ambient_lag=s.ambient_lag * scale)
            for s in DEFAULT_SENSORS]


def simulate(model: ThermalModel, sensors: list[Sensor], cycle: list[tuple[float, float]], rate: float,
             temperature_noise: float, drift_noise: float, seed: int, start: float = 0.0,
             hall: list[tuple[float, float]] | None = None):
    """Times, temperatures and drift (each error in its model's unit) of a machine following
    ``model``, run through ``cycle``. The truth is computed on a step 10 times finer than the
    log's (fewer on a long log: at most SIMULATION_POINTS) and then sampled, so that a fit does
    not see its own discretisation."""
    duration = sum(s for _, s in cycle)
    rows = int(duration * rate) + 1
    substeps = max(1, min(10, SIMULATION_POINTS // rows))   # 10 per reading, fewer on a long log
    fine = 1.0 / (rate * substeps)
    tf = np.arange(0.0, duration + fine / 2, fine)
    edges = np.cumsum([0.0] + [s for _, s in cycle])
    duty = np.array([d for d, _ in cycle] + [cycle[-1][0]])[np.clip(np.searchsorted(edges, tf, side="right") - 1,
                                                                   0, len(cycle))]
    rng = np.random.default_rng(seed)
    mean, swings = HALL[0], HALL[1] if hall is None else hall
    hall = mean + sum(a * np.sin(2 * np.pi * tf / p + rng.uniform(0, 2 * np.pi)) for a, p in swings)
    truth = {}
    for s in sensors:
        v = mean + s.ambient * (lag(tf, hall, s.ambient_lag) - mean) + s.rise * lag(tf, duty, s.time_constant)
        if s.swing:
            v = v + s.swing * (2 * np.abs(((tf + start) / s.swing_period) % 1.0 - 0.5) - 0.5)
        truth[s.name] = v
    drift = {name: em.evaluate(tf, truth, model.reference) for name, em in model.errors.items()}
    step = substeps
    t = tf[::step]
    temps = {n: v[::step] + rng.normal(0.0, temperature_noise, len(t)) for n, v in truth.items()}
    # drift_noise: um for a length error, arcsec for an angle, ppm for a ratio, whatever unit the model writes
    per = {n: {"length": 1e-3, "angle": math.pi / 648000, "ratio": 1e-6}[em.unit.kind] / em.unit.to_internal
           for n, em in model.errors.items()}
    drift = {n: v[::step] + rng.normal(0.0, drift_noise * per[n], len(t)) for n, v in drift.items()}
    return t, temps, drift


# ----------------------------------------------------------------------------- per-axis streams

@dataclass
class AxisLine:
    """What a unit of each thermal error does along one linear axis: the tool's error along
    the axis' travel, over the axis' range with the other axes at their default positions,
    fitted by a line value(P) = offset + slope * (P - reference) (mm and mm/mm per internal
    unit of the error), and the largest departure from that line (mm per unit)."""
    axis: str
    reference: float             # mm: the line's reference position (P0)
    offset: dict[str, float]
    slope: dict[str, float]
    departure: dict[str, float]


def axis_lines(machine: Machine, errors: list[str], references: dict[str, float], points: int = 41) -> list[AxisLine]:
    """Per linear axis, the line of each error (a first-order sensitivity: the thermal errors
    are small)."""
    from ..symbolic.numeric import ExactModel
    exact = ExactModel(machine)
    base = machine.nominal_values()
    for a in machine.axes:
        base[a.name] = a.to_internal(a.default_position)
    out = []
    for a in machine.axes:
        if a.unit.kind != "length":
            continue
        lo, hi = (a.to_internal(v) for v in a.limits)
        q = np.linspace(lo, hi, points)

        def tool(values):
            p, _ = exact.pose({**values, a.name: q})
            return np.stack([np.broadcast_to(np.asarray(c, float), q.shape) for c in p])

        p0 = tool(base)
        travel = (p0[:, -1] - p0[:, 0]) / (hi - lo)   # tool motion per mm of the axis
        scale = float(np.linalg.norm(travel))
        u = travel / scale
        ref = references.get(a.name, lo)
        line = AxisLine(a.name, ref, {}, {}, {})
        for e in errors:
            sym = machine.symbol(e)
            step = 1e-3 if sym.unit.kind == "length" else 1e-6   # mm or rad: well inside the linear range
            along = (u @ (tool({**base, e: step}) - p0)) / (scale * step)   # axis mm per unit of the error
            slope, offset = np.polyfit(q - ref, along, 1)
            line.offset[e], line.slope[e] = float(offset), float(slope)
            line.departure[e] = float(np.max(np.abs(along - (offset + slope * (q - ref)))))
        out.append(line)
    return out
