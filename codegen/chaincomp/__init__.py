"""chaincomp: geometric error models of machine tools from a chain of transforms."""

from .errors import ChaincompError
from .machine import Machine, load_machine
from .params import load_params

__all__ = ["ChaincompError", "Machine", "load_machine", "load_params"]
__version__ = "0.1.0"
