"""Commanded axis positions for logs and demos: a plausible toolpath for any machine."""

from __future__ import annotations

import math

import numpy as np

from ..errors import ChaincompError
from ..model.machine import Machine

# Samples per path: 1 M take 4 s and 85 MB to log (2 cores, 2026-12); 4 M is over an hour
# at 1 kHz.
MAX_SAMPLES = 4_000_000


def toolpath(machine: Machine, rate_hz: float, seconds: float, period_s: float = 5.0) -> np.ndarray:
    """Axis values (declared units, machine axis order), one row per sample.

    Linear axes trace a circle (the first two) or a slow wave (the others) around the middle
    of their range; rotary axes tilt and turn the tool with the circle: the kind of path a
    5-axis contour produces. Amplitudes stay within 40% of each range.

    Note: a tilt axis whose range is centred on zero tilts only to one side here.
    """
    n = round(rate_hz * seconds)
    if not 1 <= n <= MAX_SAMPLES:
        raise ChaincompError(f"--rate {rate_hz:g} x --seconds {seconds:g} gives {n} samples: between 1 and "
                             f"{MAX_SAMPLES} are written")
    t = np.arange(n) / rate_hz
    phase = 2 * math.pi * t / period_s
    cols = []
    linear = rotary = 0
    for a in machine.axes:
        lo, hi = a.limits
        mid, amp = 0.5 * (lo + hi), 0.4 * (hi - lo)
        if a.unit.kind == "length":
            amp = min(amp, 100.0 * (1 if a.unit.name == "mm" else 1 / a.unit.to_internal))
            wave = [np.cos(phase), np.sin(phase), np.sin(2 * phase)][min(linear, 2)]
            linear += 1
        else:
            amp = min(amp, 45.0 * math.pi / 180 / a.unit.to_internal)
            # the tilt stays between a quarter and all of its amplitude: away from the
            # singular pose where the tool lies along the next rotary axis
            wave = [0.625 + 0.375 * np.sin(phase), np.sin(phase)][min(rotary, 1)]
            rotary += 1
        cols.append(np.clip(mid + amp * wave, lo, hi))
    out = np.stack(cols, axis=1)
    if not np.isfinite(out).all():   # limits near the float range: their middle overflows
        raise ChaincompError(f"the toolpath of {machine.name} is not finite: check its axis limits", machine.file)
    return out
