"""A fit as the numbers of a calibration report (analysis.calibration_report): what identify and
probe fit hand to ``--report OUT.html``."""

from __future__ import annotations

import datetime
import math
import os

import numpy as np

from ..analysis.calibration_report import Calibration, Dispersion, Residual, Value
from ..errors import ChaincompError
from ..measure.identify import Fit
from ..measure.identify_report import _shown
from ..measure.probe import NUISANCE, ProbeFit
from ..measure.table import COMPONENTS, OBSERVED, Table
from ..model.display import display_unit
from .common import check_output


def check_report(path: str | None, *inputs: str | None) -> None:
    """--report FILE.html: never an input, and named as what it is (a browser opens it by the name)."""
    if path is None:
        return
    check_output(path, *inputs, option="--report")
    if os.path.splitext(path)[1].lower() not in (".html", ".htm"):
        raise ChaincompError(f"--report {path}: the file name must end in .html")


def now() -> str:
    return datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")


def calibration_of(fit: Fit, table: Table, setup: list[tuple[str, str]], units: str) -> Calibration:
    """The report's numbers of an identify fit: per set-up the size of the tool point's residual
    (or, with no point measured, of the direction's or orientation's) before the fit (every
    fitted error zero) and after it; per measured coordinate of that kind its rms residual over
    the set-ups (the dispersion)."""
    m = fit.machine
    point = any(c in fit.measured for c in COMPONENTS)
    kind = "length" if point else "angle"
    unit = display_unit(kind, units)
    cols = [k for k, c in enumerate(OBSERVED) if c in fit.measured and (c in COMPONENTS) == point]
    shown = [OBSERVED[k] for k in cols]

    def size(r: np.ndarray) -> np.ndarray:          # per set-up, nan where none of cols was measured
        part = r[:, cols]
        with np.errstate(invalid="ignore"):
            return np.where(np.isnan(part).all(axis=1), math.nan, np.sqrt(np.nansum(part ** 2, axis=1))) \
                / unit.to_internal

    def rms(r: np.ndarray) -> float:
        v = r[~np.isnan(r)]
        return math.sqrt(float(np.mean(v ** 2))) / unit.to_internal if v.size else math.nan

    before, after = size(fit.residuals_before), size(fit.residuals_after)
    residuals = [Residual(f"line {line}", float(b), float(a)) for line, b, a in zip(table.lines, before, after)]
    dispersion = [Dispersion(c, rms(fit.residuals_before[:, k]), rms(fit.residuals_after[:, k]))
                  for c, k in zip(shown, cols)]
    byname = {p.name: p for p in fit.params}
    values = []
    for name, v in fit.estimates.items():
        factor, u = _shown(fit, byname[name], units)
        values.append(Value(name, v / factor, fit.uncertainties[name] / factor, u))
    plan_columns = ["CSV line"] + [f"{a.name} [{a.unit.name}]" for a in m.axes] + ["measured"]
    plan = [[str(line)] + [f"{a.from_internal(table.axes[a.name][i]):.6g}" for a in m.axes]
            + [", ".join(c for k, c in enumerate(OBSERVED) if not math.isnan(fit.residuals_before[i, k]))]
            for i, line in enumerate(table.lines)]
    not_seen = [(n, "assumed zero (--assume-zero): not fitted") for n in fit.assumed_zero]
    not_seen += list(fit.unidentifiable.items()) + list(fit.redundant.items())
    summary = [("set-ups", str(fit.setups)),
               ("coordinates measured", f"{fit.observations} ({', '.join(fit.measured)})"),
               ("errors fitted", f"{len(fit.fitted)} ({len(fit.params)} parameters), "
                                 f"{len(fit.estimates)} given a value"),
               ("rank, condition number", f"{fit.rank}, {fit.condition:.4g} (Jacobian columns scaled to unit norm)"),
               ("rms residual after the fit", f"{rms(fit.residuals_after[:, cols]):.4g} {unit.name} "
                                              f"({', '.join(shown)})"),
               ("degrees of freedom", f"{fit.dof:.4g}"),
               ("Gauss-Newton", f"{'converged' if fit.converged else 'NOT converged'} after {fit.iterations} "
                                "iterations on the exact model")]
    if fit.chi2 is not None:
        summary.append(("chi2/dof", f"{fit.chi2:.3g}"))
    warnings = ([fit.misfit] if fit.misfit else []) + [f"note: {n}" for n in fit.notes]
    if fit.suggested_zero:
        warnings.append("Some errors could not be given a value: fit a minimal set (--minimal) or assume these "
                        "zero as well: " + ", ".join(fit.suggested_zero))
    return Calibration(
        "chaincomp identify", m.name, now(), setup, plan_columns, plan, unit.name, residuals,
        f"Each measured {'tool-point coordinate' if point else 'direction component'}'s rms residual over the "
        "set-ups, before and after the fit (a probing fit reports the spread of the sphere centres per rotary "
        "axis here, as KinematicsOpt's measured and optimised dispersion).",
        dispersion, values, fit.correlation.tolist() if fit.correlation is not None else None, not_seen,
        summary, warnings)


def calibration_of_probe(pf: ProbeFit, source: str, units: str = "people") -> Calibration:
    """The report's numbers of a probing fit: per rotary position the distance of its sphere
    centre from where the model puts the sphere, before the fit (every error zero or held, the
    sphere where it fits best) and after it; per rotary axis KinematicsOpt's dispersion (the
    largest distance between two centres as that axis turns alone). The sphere's own offset is
    a nuisance parameter: in the summary, not among the values."""
    f, m = pf.fit, pf.machine
    unit, angle = display_unit("length", units), display_unit("angle", units)
    rotary = list(pf.positions[0]) if pf.positions else []

    def at(p: dict) -> str:
        return ", ".join(f"{n} = {m.symbol(n).from_internal(v):.6g} {m.symbol(n).unit.name}" for n, v in p.items())

    residuals = [Residual(at(p), float(np.linalg.norm(b)) / unit.to_internal, float(np.linalg.norm(a)) / unit.to_internal)
                 for p, b, a in zip(pf.positions, pf.residuals_before, pf.residuals_after)]
    dispersion = [Dispersion(k, b / unit.to_internal, a / unit.to_internal) for k, (b, a) in pf.dispersion.items()]
    byname = {p.name: p for p in f.params}
    names = list(f.estimates)
    keep = [i for i, n in enumerate(names) if n not in NUISANCE]
    values = []
    for i in keep:
        factor, u = _shown(f, byname[names[i]], units)
        values.append(Value(names[i], f.estimates[names[i]] / factor, f.uncertainties[names[i]] / factor, u))
    plan_columns = [f"{n} [{m.symbol(n).unit.name}]" for n in rotary] + ["approaches", "touches", "probed radius [mm]"]
    plan = []
    for p in pf.positions:
        cs = [c for c in pf.centres if c.group.rotary == p]
        plan.append([f"{m.symbol(n).from_internal(p[n]):.6g}" for n in rotary]
                    + [" ".join(c.group.approach for c in cs), str(sum(len(c.group.points) for c in cs)),
                       ", ".join(f"{c.radius:.4f}" for c in cs)])
    summary = [("sphere centres", f"{len(pf.centres)} at {len(pf.positions)} rotary positions"),
               ("rank, condition number", f"{f.rank}, {f.condition:.4g} (Jacobian columns scaled to unit norm)"),
               ("rms centre residual after the fit", f"{f.rms / unit.to_internal:.4g} {unit.name}"),
               ("sphere's offset from its nominal place (x, y, z)",
                ", ".join(f"{x / unit.to_internal:.4g}" for x in pf.sphere_offset) + f" {unit.name}"),
               ("Gauss-Newton", f"{'converged' if f.converged else 'NOT converged'} after {f.iterations} iterations "
                                "on the exact model")]
    summary += [(f"rotary backlash of {n}", f"{v / angle.to_internal:.4g} ± {s / angle.to_internal:.2g} {angle.name}")
                for n, (v, s) in pf.backlash.items()]
    setup = [("probe logs", source),
             ("sphere's nominal centre", ", ".join(f"{x:g}" for x in pf.sphere.centre) + f" {m.length_unit}"),
             ("sphere radius, stylus radius", f"{pf.sphere.radius:g} {m.length_unit}, {pf.sphere.stylus:g} "
                                              f"{m.length_unit}"),
             ("held at given values (--hold)", ", ".join(pf.held) or "none")]
    not_seen = list(pf.gauge.items()) + [(n, "assumed zero (--assume-zero): not fitted")
                                         for n in f.assumed_zero if n not in pf.held and n not in pf.gauge]
    correlation = f.correlation[np.ix_(keep, keep)].tolist() if f.correlation is not None else None
    return Calibration(
        "chaincomp probe fit", m.name, now(), setup, plan_columns, plan, unit.name, residuals,
        "Per rotary axis the largest distance between two sphere centres of positions that differ in that axis "
        "alone (how far the sphere seemed to move as the axis turned: KinematicsOpt's measured and optimised "
        "dispersion), and over all positions.",
        dispersion, values, correlation, not_seen, summary, [f"note: {n}" for n in f.notes])
