import contextlib
import functools
import io
import json
import os
import subprocess
import sys

import pytest

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
MACHINES = os.path.join(ROOT, "configs", "machines")
PARAMS = os.path.join(ROOT, "configs", "params")
# every machine shipped in configs/machines/, so a new one joins every fixture-based test
BUNDLED = sorted(os.path.splitext(f)[0] for f in os.listdir(MACHINES) if f.endswith(".yaml"))


def machine_path(name: str) -> str:
    return os.path.join(MACHINES, name + ".yaml")


def derived(path: str, order: int):
    """derive(machine, order) of a machine file, once a session: an arm's order 2 takes minutes,
    and test_gain, test_jets and test_truncation all compare against the same derivations.
    Shared: only read it, never change it."""
    return _derived(os.path.abspath(path), order)


def truncated(path: str, order: int):
    """TruncatedModel of derived(path, order), once a session (it keeps its lambdified formulas)."""
    return _truncated(os.path.abspath(path), order)


@functools.cache
def _derived(path: str, order: int):
    from chaincomp import derive, load_machine
    return derive(load_machine(path), order)


@functools.cache
def _truncated(path: str, order: int):
    from chaincomp import TruncatedModel
    return TruncatedModel(_derived(path, order))


def run_cli(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    proc = subprocess.run([sys.executable, "-m", "chaincomp.cli.main", *args], capture_output=True,
                          text=True, cwd=ROOT)
    if check and proc.returncode != 0:
        raise AssertionError(f"chaincomp {' '.join(args)} exited {proc.returncode}:\n{proc.stderr}")
    return proc


def cli(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    """run_cli's result from chaincomp's entry point (cli.main.main) in this process: the same
    verb, options, output and exit code, without an interpreter's start-up (about 1 s of CPU a
    call). Keep run_cli, a real process, for at least one test of each verb: the exit path."""
    from chaincomp.cli.main import main
    out, err, here = io.StringIO(), io.StringIO(), os.getcwd()
    os.chdir(ROOT)   # as run_cli's cwd
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main([str(a) for a in args])
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else 1
    finally:
        os.chdir(here)
    proc = subprocess.CompletedProcess(["chaincomp", *args], code, out.getvalue(), err.getvalue())
    if check and code != 0:
        raise AssertionError(f"chaincomp {' '.join(map(str, args))} exited {code}:\n{proc.stderr}")
    return proc


def eval_json(*args: str) -> dict:
    return json.loads(run_cli("eval", *args, "--json").stdout)


@pytest.fixture(params=BUNDLED)
def bundled(request):
    from chaincomp import load_machine
    return load_machine(machine_path(request.param))


def _netns_available() -> bool:
    try:
        return subprocess.run(["unshare", "-rn", "true"], capture_output=True).returncode == 0
    except FileNotFoundError:
        return False


# LCM tests across processes run inside a network namespace they make (tests/e2e/netns.sh)
needs_netns = pytest.mark.skipif(not _netns_available(),
                                 reason="unprivileged network namespaces (unshare -rn) are not permitted here")


def pytest_configure(config):
    # the fast tier (tools/test --fast) leaves these out; CI runs every test
    config.addinivalue_line("markers", "slow: a heavy end-to-end test (builds, daemons, LinuxCNC, long sweeps)")
