"""Calibration poses for arms: N poses within the joint limits that maximise an observability
index of the scaled identification Jacobian (the one ``identify`` fits with).

The Jacobian of the measured tool-point coordinates in the errors is taken at zero errors by
the complex step, as identify does, over a seeded random pool of candidate poses. Its columns
are scaled to unit rms over the pool and projected on the combinations of errors the pool can
identify at all (a redundant parameter set would pin every index at zero). Then:

* greedy: poses are added one at a time, each the candidate that most increases
  log det(JᵀJ) (the determinant lemma on 3-row blocks, a Woodbury update of the inverse);
* exchange passes (DETMAX-like): a chosen pose is swapped for a candidate while that improves
  the index asked for. For ``o1`` (Borm & Menq's O1 = (σ1···σr)^(1/r)/√N, a monotone function
  of the determinant) every chosen pose is tried against the candidates the determinant
  prefers; for ``min-sv`` (σr, the smallest singular value) swaps are proposed from the
  candidates that see the weakest direction and judged on σr itself.

The pool and the work are bounded; everything is drawn from one numpy generator seeded by
``seed``, so the same seed gives the same poses.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass

import numpy as np

from ..errors import ChaincompError
from ..escape import one_line
from ..model.machine import Machine
from ..output import write_file
from ..symbolic.derive import COMPONENTS
from ..symbolic.numeric import ExactModel
from .identify import pose_points
from .lsq import numeric_rank, step_derivatives

MAX_POSES = 20_000
DEFAULT_POSES = 50
MAX_POOL = 50_000
INDICES = ("min-sv", "o1")
_CHUNK = 2_000            # poses per Jacobian evaluation: bounds the complex intermediate
_WORK = 3e9               # flops the greedy and exchange passes may spend (about 10 s here)


def point_jacobian(machine: Machine, model: ExactModel, axes: dict[str, np.ndarray],
                   errors: list[str], measure=COMPONENTS, say=None) -> np.ndarray:
    """(rows, len(measure), len(errors)): the measured tool-point coordinates' derivatives in
    the errors at zero errors, internal units, by the complex step (central differences where
    the chain cannot take complex values), as identify's fit takes them."""
    idx = [COMPONENTS.index(c) for c in measure]
    rows = len(next(iter(axes.values())))
    n = len(errors)
    out = np.empty((rows, len(idx), n))
    for start in range(0, rows, _CHUNK):
        part = {k: np.asarray(v)[start:start + _CHUNK] for k, v in axes.items()}

        def points(P):        # (k, n) error sets -> (k, rows, 3)
            return pose_points(machine, model, part, {e: P[:, j:j + 1] for j, e in enumerate(errors)})
        d = step_derivatives(points, np.zeros(n), np.eye(n))         # (n, rows, 3)
        d = np.broadcast_to(d, (n, len(next(iter(part.values()))), 3))
        out[start:start + _CHUNK] = np.transpose(d[:, :, idx], (1, 2, 0))
        if say:
            say(f"Jacobian: {min(start + _CHUNK, rows)} of {rows} candidate poses")
    return out


def is_arm(machine: Machine) -> bool:
    """An arm gets a pose design by default: every axis a revolute joint (an angle) of a serial
    chain (no structural loop), written as dh/mdh joints or four or more of them (an angle grid
    over four axes already has 256 set-ups, past what the paper's search can pair)."""
    return bool(machine.axes) and all(s.unit.kind == "angle" for s in machine.axes) \
        and not machine.workpiece_chain and (bool(machine.joints) or len(machine.axes) >= 4)


def index_value(blocks: np.ndarray, index: str) -> float:
    """The index of a set of poses: blocks (poses, coords, r), already scaled and projected."""
    a = blocks.reshape(-1, blocks.shape[-1])
    s = np.linalg.svd(a, compute_uv=False)
    r = blocks.shape[-1]
    if len(s) < r:
        return 0.0
    if index == "min-sv":
        return float(s[r - 1])
    return float(math.exp(np.log(np.maximum(s[:r], 1e-300)).mean()) / math.sqrt(blocks.shape[0]))


@dataclass
class Design:
    machine: Machine
    errors: list[str]                 # errors in the Jacobian (not assumed zero)
    measure: list[str]
    index: str
    seed: int
    pool: int
    rank: int                         # combinations of the errors the pool identifies
    invisible: list[str]              # errors that move no measured coordinate at any pool pose
    poses: dict[str, np.ndarray]      # axis -> values (internal units), the chosen poses
    value: float                      # index of the chosen poses
    random_values: list[float]        # index of random sets of the same size from the pool
    greedy_value: float               # index after the greedy pass, before the exchanges
    exchanges: int                    # swaps accepted

    def __len__(self) -> int:
        return len(next(iter(self.poses.values())))

    @property
    def random_median(self) -> float:
        return float(np.median(self.random_values))

    @property
    def ratio(self) -> float | None:
        """None where random sets of this size do not see every combination (index 0)."""
        return self.value / self.random_median if self.random_median > 0 else None


class _Progress:
    def __init__(self, enabled: bool):
        self.enabled, self.t0, self.last = enabled, time.monotonic(), 0.0

    def __call__(self, msg: str) -> None:
        now = time.monotonic() - self.t0
        if self.enabled and now - self.last >= 1.0:
            print(f"chaincomp protocol: {msg} ({now:.0f} s)", file=sys.stderr)
            self.last = now


def design_poses(machine: Machine, n: int, seed: int, index: str = "min-sv", measure=COMPONENTS,
                 assume_zero=(), pool: int | None = None, progress: bool = True,
                 fixed: dict[str, float] | None = None) -> Design:
    """N poses from a pool of random ones (uniform within the limits; ``fixed`` axes held at
    their internal value) that maximise ``index``; see the module's docstring."""
    if index not in INDICES:
        raise ChaincompError(f"--index: expected one of {', '.join(INDICES)}, got {index!r}")
    if not 1 <= n <= MAX_POSES:
        raise ChaincompError(f"--poses: expected 1 <= N <= {MAX_POSES}, got {n}")
    pool = pool if pool is not None else min(max(20 * n, 2000), MAX_POOL)
    if not n < pool <= MAX_POOL:
        raise ChaincompError(f"--pool: expected N < POOL <= {MAX_POOL} (N = {n}), got {pool}")
    errors = [s.name for s in machine.errors if s.name not in assume_zero]
    if not errors:
        raise ChaincompError("--assume-zero: every error is assumed zero, nothing is left to identify")
    say = _Progress(progress)
    rng = np.random.default_rng(seed)
    fixed = fixed or {}
    cand = {s.name: s.to_internal(rng.uniform(*s.limits, pool)) for s in machine.axes}
    cand.update({k: np.full(pool, v) for k, v in fixed.items()})
    jac = point_jacobian(machine, ExactModel(machine), cand, errors, measure, say)   # (pool, c, n)
    scale = np.sqrt((jac ** 2).sum(axis=(0, 1)) / pool)
    visible = scale > 1e-12 * max(scale.max(initial=0.0), 1e-300)
    invisible = [e for e, v in zip(errors, visible) if not v]
    if not visible.any():
        raise ChaincompError(f"none of the {len(errors)} errors moves the measured coordinates "
                             f"({', '.join(measure)}) at any pose: nothing to identify")
    j = jac[:, :, visible] / scale[visible]
    _, s, vt = np.linalg.svd(j.reshape(-1, j.shape[-1]), full_matrices=False)
    r = numeric_rank(s)
    blocks = j @ vt[:r].T                                                        # (pool, c, r)
    if n * len(measure) < r:
        raise ChaincompError(f"--poses {n}: {n} poses give {n * len(measure)} coordinates for the {r} "
                             f"combinations of errors to identify: give at least "
                             f"{math.ceil(r / len(measure))} poses")
    chosen = _greedy(blocks, n, rng, say)
    greedy_value = index_value(blocks[chosen], index)
    chosen, swaps = _exchange(blocks, chosen, index, rng, say)
    value = index_value(blocks[chosen], index)
    randoms = [index_value(blocks[rng.choice(pool, n, replace=False)], index) for _ in range(5)]
    poses = {k: v[chosen] for k, v in cand.items()}
    return Design(machine, errors, list(measure), index, seed, pool, r, invisible, poses, value,
                  randoms, greedy_value, swaps)


def _budget(n_eval: int, cost: float) -> int:
    return max(1, min(n_eval, int(_WORK / max(cost, 1.0))))


def _greedy(blocks: np.ndarray, n: int, rng, say) -> np.ndarray:
    """Add the pose that most increases log det(δI + JᵀJ), n times. Where the pool and n make
    that too much work, each step looks at a random sample of the candidates."""
    pool, c, r = blocks.shape
    ridge = 1e-6
    inv = np.eye(r) / ridge
    free = np.ones(pool, bool)
    k = _budget(pool, n * c * r * r * 2.0 / 1.0)           # candidates scored per step
    k = min(pool, max(k, 64))
    chosen = []
    for step in range(n):
        idx = np.flatnonzero(free)
        if len(idx) > k:
            idx = rng.choice(idx, k, replace=False)
        b = blocks[idx]                                      # (k, c, r)
        g = np.eye(c) + np.einsum("kcr,rs,kds->kcd", b, inv, b, optimize=True)
        best = idx[int(np.argmax(np.linalg.slogdet(g)[1]))]
        bb = blocks[best]
        w = inv @ bb.T
        inv = inv - w @ np.linalg.solve(np.eye(c) + bb @ w, w.T)
        free[best] = False
        chosen.append(best)
        say(f"greedy: {step + 1} of {n} poses")
    return np.array(chosen)


def _exchange(blocks: np.ndarray, chosen: np.ndarray, index: str, rng, say, tries: int = 24):
    """Swap a chosen pose for a candidate while that improves the index: each round proposes
    the ``tries`` candidates that add most (for min-sv: that see the weakest direction most)
    against the ``tries`` chosen poses that cost least, and takes the best swap; bounded work."""
    pool, c, r = blocks.shape
    n = len(chosen)
    chosen = chosen.copy()
    free = np.ones(pool, bool)
    free[chosen] = False
    info = np.einsum("kcr,kcs->rs", blocks[chosen], blocks[chosen])
    value = index_value(blocks[chosen], index)
    rounds = min(4 * n + 20, _budget(10 ** 6, 4 * tries * tries * r ** 3 * 4.0 + pool * c * r * 2.0))
    swaps = 0
    for it in range(rounds):
        cand = np.flatnonzero(free)
        if index == "min-sv":
            weak = np.linalg.eigh(info)[1][:, 0]
            adds = cand[np.argsort(-np.linalg.norm(blocks[cand] @ weak, axis=1), kind="stable")[:tries]]
            order = np.argsort(np.linalg.norm(blocks[chosen] @ weak, axis=1), kind="stable")
            drop = chosen[order[:4 * tries]]       # all of them, for a small set
        else:
            inv = np.linalg.inv(info)
            sample = cand if len(cand) <= 4096 else rng.choice(cand, 4096, replace=False)
            g = np.eye(c) + np.einsum("kcr,rs,kds->kcd", blocks[sample], inv, blocks[sample], optimize=True)
            adds = sample[np.argsort(-np.linalg.slogdet(g)[1], kind="stable")[:tries]]
            h = np.eye(c) - np.einsum("kcr,rs,kds->kcd", blocks[chosen], inv, blocks[chosen], optimize=True)
            drop = chosen[np.argsort(-np.linalg.slogdet(h)[1], kind="stable")[:tries]]   # cost least to lose
        best = (value, None, None)
        for out_ in drop:
            for in_ in adds:
                ev = np.linalg.eigvalsh(info - blocks[out_].T @ blocks[out_] + blocks[in_].T @ blocks[in_])
                if ev[0] <= 0:
                    continue
                t = math.sqrt(ev[0]) if index == "min-sv" else math.exp(0.5 * np.log(ev).mean()) / math.sqrt(n)
                if t > best[0] * (1 + 1e-9):
                    best = (t, out_, in_)
        if best[1] is None:
            break
        value, out_, in_ = best
        chosen[chosen == out_] = in_
        free[out_], free[in_] = True, False
        info = info - blocks[out_].T @ blocks[out_] + blocks[in_].T @ blocks[in_]
        swaps += 1
        say(f"exchange {it + 1}: index {value:.4g}")
    return chosen, swaps


# ----------------------------------------------------------------------------- output

_WHAT = {"min-sv": "the smallest singular value of the scaled identification Jacobian",
         "o1": "Borm & Menq's O1, (s1 s2 ... sr)^(1/r) / sqrt(N), of the scaled identification Jacobian"}


def write_poses(path: str, design: Design, command: str) -> None:
    """The set-ups CSV that identify and simulate-measurements --setups read: one column per
    axis (declared unit, 15 digits), then the measured coordinates, empty, to fill in."""
    m = design.machine
    names = [s.name for s in m.axes]
    out = [f"# {command}: {len(design)} poses, {design.index} {design.value:.6g} "
           f"(random sets of the same size: {design.random_median:.6g})\n",
           f"# axes in their declared units; fill in the measured {', '.join(design.measure)} "
           f"(tool point, {m.length_unit}) for chaincomp identify\n",
           ",".join(names + design.measure) + "\n"]
    for i in range(len(design)):
        cells = [f"{m.symbol(a).from_internal(design.poses[a][i]):.15g}" for a in names]
        out.append(",".join(cells + [""] * len(design.measure)) + "\n")
    write_file(path, "".join(out))   # beside it, then renamed: never a short file


def design_json(design: Design, output: str | None) -> dict:
    m = design.machine
    return {
        "machine": m.name, "file": m.file, "kind": "pose design", "poses": len(design),
        "index": design.index, "index_meaning": _WHAT[design.index], "value": design.value,
        "random_values": design.random_values, "random_median": design.random_median, "ratio": design.ratio,
        "greedy_value": design.greedy_value, "exchanges": design.exchanges,
        "seed": design.seed, "pool": design.pool, "measured": design.measure, "errors": design.errors,
        "rank": design.rank, "invisible": design.invisible, "output": output,
        "units": {s.name: s.unit.name for s in m.axes},
        "setups": [{a: m.symbol(a).from_internal(float(v[i])) for a, v in design.poses.items()}
                   for i in range(len(design))],
    }


def _redundant(design: Design) -> str:
    k = len(design.errors) - len(design.invisible) - design.rank
    return f"{k} combination{'s' if k != 1 else ''} of them no pose can see" if k > 0 else ""


def design_text(design: Design, output: str | None) -> str:
    m = design.machine
    lines = [f"POSE DESIGN for {m.name} ({one_line(m.file)}): {len(design)} poses within the axis limits, "
             f"seed {design.seed}, from {design.pool} random candidates",
             f"Measured: {', '.join(c.upper() for c in design.measure)} of the tool point; "
             f"{len(design.errors)} errors, of which the pool identifies {design.rank} independent combinations"
             + (f"; {_redundant(design)} (identify names the errors in them)" if _redundant(design) else ""),
             f"Index {design.index}: {_WHAT[design.index]}",
             f"  chosen poses   {design.value:.6g}   (greedy {design.greedy_value:.6g}, "
             f"then {design.exchanges} exchanges)",
             f"  random poses   {design.random_median:.6g}   (median of {len(design.random_values)} sets of "
             f"{len(design)} from the pool)",
             f"  ratio          " + (f"{design.ratio:.3f}" if design.ratio is not None else
                                      "(random sets of this size do not see every combination)")]
    if design.invisible:
        lines.append(f"Not seen at any pose: {', '.join(design.invisible)} (they move no measured coordinate)")
    if output:
        lines.append(f"wrote {output}: measure {', '.join(design.measure)} at each pose, then "
                     f"'chaincomp identify {m.file} {output}' (or try it with "
                     f"'chaincomp simulate-measurements --setups {output}')")
    else:
        lines.append("(-o POSES.csv writes the poses; --format json lists them)")
    return "\n".join(lines)
