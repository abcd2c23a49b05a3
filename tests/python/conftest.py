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


def run_cli(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    proc = subprocess.run([sys.executable, "-m", "chaincomp.cli.main", *args], capture_output=True,
                          text=True, cwd=ROOT)
    if check and proc.returncode != 0:
        raise AssertionError(f"chaincomp {' '.join(args)} exited {proc.returncode}:\n{proc.stderr}")
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
