"""pytest's hooks and fixtures; what the tests share as functions is in helpers.py."""

import os
import sys

import pytest

# the tests live in subject folders (model/, emit/, ...) and import helpers and arm_models from here
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from helpers import BUNDLED, machine_path  # noqa: E402


@pytest.fixture(params=BUNDLED)
def bundled(request):
    from chaincomp import load_machine
    return load_machine(machine_path(request.param))


@pytest.fixture(scope="module")
def measurements(tmp_path_factory) -> str:
    """Tool points of vmc_xyz at 30 random set-ups, no errors, 1 um noise (input data only)."""
    from chaincomp.cli.main import main
    path = tmp_path_factory.mktemp("meas") / "meas.csv"
    assert main(["simulate-measurements", machine_path("vmc_xyz"), "--setups", "random:30", "--noise", "1um",
                 "-o", str(path)]) == 0
    return str(path)


def pytest_configure(config):
    # the fast tier (tools/test --fast) leaves these out; CI runs every test
    config.addinivalue_line("markers", "slow: a heavy end-to-end test (builds, daemons, LinuxCNC, long sweeps)")
