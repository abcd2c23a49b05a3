"""The grammar of a number a user writes outside YAML: an option value, a CSV cell."""

from __future__ import annotations

import math
import re

# [0-9], not \d: \d takes every script's digits, which float() then reads as numbers.
DECIMAL = re.compile(r"[+-]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?")


def parse_number(text: str) -> float:
    """A finite number written in plain ASCII decimals: float() alone would also take 'nan',
    'inf', '1_000' and other scripts' digits. Raises ValueError with the reason."""
    t = text.strip(" \t\r\n")   # str.strip() alone would also take other scripts' spaces (U+3000)
    if DECIMAL.fullmatch(t):
        value = float(t)
        if math.isfinite(value):
            return value
        raise ValueError(f"expected a finite number, got {text!r}")   # e.g. 1e400
    try:
        value = float(t)
    except ValueError:
        raise ValueError(f"expected a number, got {text!r}") from None
    raise ValueError(f"expected a {'plain decimal' if math.isfinite(value) else 'finite'} number, got {text!r}")
