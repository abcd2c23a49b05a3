"""chaincomp: geometric error models of machine tools from a chain of transforms.

The Python API (values in internal units: mm, rad)::

    m = load_machine("M.yaml")                   # validated; ChaincompError names file:line: field
    errors = load_params("P.yaml", m)            # {name: value or Table/Polynomial}
    exact = ExactModel(m)                        # the chain multiplied numerically, no truncation
    point, direction = exact.pose({"X": 10.0, ...})          # constants at nominal, errors at 0
    d_point, d_direction = exact.error({"X": 10.0, **errors})
    d = derive(m, order=2)                       # truncated series; d.gain(d.point[0]) ...
    TruncatedModel(d).error({...}, order=1)
    lint(m)                                      # warnings: errors or axes that never move the tool
"""

from .budget import Budget, compute as compute_budget, make_grid
from .derive import Derivation, derive
from .errors import ChaincompError
from .lint import Finding, lint
from .machine import Machine, Symbol, load_machine
from .numeric import ExactModel, TruncatedModel
from .params import load_params
from .tolerances import load_tolerances

__all__ = ["Budget", "ChaincompError", "Derivation", "ExactModel", "Finding", "Machine", "Symbol",
           "TruncatedModel", "compute_budget", "derive", "lint", "load_machine", "load_params",
           "load_tolerances", "make_grid"]
__version__ = "0.1.0"
