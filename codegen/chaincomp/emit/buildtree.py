"""Where the C++ build puts what the Python side runs: binaries and LCM bindings."""

from __future__ import annotations

import os
import sys

from ..errors import ChaincompError

_ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", ".."))


def build_dir() -> str:
    """build/ of this checkout, or $CHAINCOMP_BUILD_DIR."""
    return os.environ.get("CHAINCOMP_BUILD_DIR", os.path.join(_ROOT, "build"))


def binary(name: str) -> str:
    path = os.path.join(build_dir(), "bin", name)
    if not os.access(path, os.X_OK):
        raise ChaincompError(f"{path} is missing: build the C++ first (tools/setup)")
    return path


def import_lcmtypes():
    """The generated Python LCM bindings (package chaincomp_lcm)."""
    path = os.path.join(build_dir(), "lcmtypes")
    if not os.path.isdir(os.path.join(path, "chaincomp_lcm")):
        raise ChaincompError(f"{path}/chaincomp_lcm is missing: build the C++ first (tools/setup)")
    if path not in sys.path:
        sys.path.insert(0, path)
    import chaincomp_lcm
    return chaincomp_lcm
