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

import importlib

# The API's names, imported when first used: a command line verb imports only what it needs
# (the symbolic modules pull in sympy, ~0.5 s).
_WHERE = {"Budget": "analysis.budget", "compute_budget": "analysis.budget", "make_grid": "analysis.budget",
          "Finding": "analysis.lint", "lint": "analysis.lint", "load_tolerances": "analysis.tolerances",
          "ChaincompError": "errors", "Machine": "model.machine", "Symbol": "model.machine",
          "load_machine": "model.machine", "load_params": "model.params", "Derivation": "symbolic.derive",
          "derive": "symbolic.derive", "ExactModel": "symbolic.numeric", "TruncatedModel": "symbolic.numeric"}
_ORIGINAL = {"compute_budget": "compute"}


def __getattr__(name: str):
    if name not in _WHERE:
        raise AttributeError(f"module 'chaincomp' has no attribute {name!r}")
    return getattr(importlib.import_module(f".{_WHERE[name]}", __name__), _ORIGINAL.get(name, name))


__all__ = ["Budget", "ChaincompError", "Derivation", "ExactModel", "Finding", "Machine", "Symbol",
           "TruncatedModel", "compute_budget", "derive", "lint", "load_machine", "load_params",
           "load_tolerances", "make_grid"]
__version__ = "0.1.0"
