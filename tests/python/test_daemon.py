"""chaincompd: start-up errors (no LCM traffic), and the end-to-end scenarios of
tests/e2e/, each run inside a network namespace made by tests/e2e/netns.sh."""

import os
import subprocess

import pytest

from conftest import ROOT, machine_path

DAEMON = os.path.join(ROOT, "build", "bin", "chaincompd")
NETNS = os.path.join(ROOT, "tests", "e2e", "netns.sh")
PY = os.path.join(ROOT, ".venv", "bin", "python")
PARAMS = os.path.join(ROOT, "configs", "params", "five_axis_ac-demo.yaml")


def _netns_available() -> bool:
    try:
        return subprocess.run(["unshare", "-rn", "true"], capture_output=True).returncode == 0
    except FileNotFoundError:
        return False


needs_netns = pytest.mark.skipif(not _netns_available(),
                                 reason="unprivileged network namespaces (unshare -rn) are not permitted here")


def run_daemon(*args):
    return subprocess.run([DAEMON, *args], capture_output=True, text=True, timeout=20)


def test_daemon_help():
    proc = run_daemon("--help")
    assert proc.returncode == 0 and "--machine M.yaml --params P.yaml" in proc.stdout


@pytest.mark.parametrize("make, words", [
    (lambda t: ["--machine", machine_path("five_axis_ac")], "--machine and --params are required"),
    (lambda t: ["--machine", str(t / "none.yaml"), "--params", PARAMS], "none.yaml: cannot read file"),
    (lambda t: ["--machine", machine_path("five_axis_ac"), "--params", PARAMS, "--model", str(t / "none.so")],
     "none.so: cannot load"),
    (lambda t: ["--machine", machine_path("five_axis_ac"), "--params", _write(t, "p.yaml", "values:\n  EXX: 1 deg\n")],
     "p.yaml:2: values.EXX: unit 'deg' is a angle unit"),
    (lambda t: ["--machine", machine_path("five_axis_ac"), "--params", PARAMS, "--config",
                _write(t, "r.yaml", "status_period: fast\n")], "r.yaml:1: status_period: expected a number"),
    (lambda t: ["--machine", machine_path("five_axis_ac"), "--params", PARAMS, "--config",
                _write(t, "r.yaml", "axes:\n  W: {max_step: 1}\n")], "r.yaml:2: axes.W: no such axis"),
    (lambda t: ["--machine", machine_path("five_axis_ac"), "--params", PARAMS, "--config",
                _write(t, "r.yaml", "lcm_url: \"bogus://nowhere\"\n")], "cannot open LCM at 'bogus://nowhere'"),
    (lambda t: ["--frobnicate"], "unexpected argument '--frobnicate'"),
])
def test_daemon_startup_errors(tmp_path, make, words):
    proc = run_daemon(*make(tmp_path))
    assert proc.returncode == 2, proc.stderr
    assert words in proc.stderr


def _write(tmp, name, text):
    path = tmp / name
    path.write_text(text)
    return str(path)


def _scenario(*args, timeout=120):
    proc = subprocess.run([NETNS, PY, *args], capture_output=True, text=True, cwd=ROOT, timeout=timeout)
    print(proc.stdout)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout


@needs_netns
@pytest.mark.parametrize("rate", [1000, 10000])
def test_stream_end_to_end(rate):
    out = _scenario("tests/e2e/e2e_stream.py", str(rate), "10000")
    assert "heap allocations after warm-up 0" in out


@needs_netns
def test_bad_input_and_random_payloads():
    _scenario("tests/e2e/e2e_robust.py", "100000")


@needs_netns
def test_switching_is_bumpless():
    _scenario("tests/e2e/e2e_switch.py")


@needs_netns
def test_replay_equals_daemon_bit_for_bit(tmp_path):
    log = tmp_path / "axes.lcmlog"
    subprocess.run([PY, "-m", "chaincomp.cli.main", "simulate-log", machine_path("five_axis_ac"), "-o", str(log),
                    "--seconds", "2"], check=True, capture_output=True, cwd=ROOT)
    out = _scenario("tests/e2e/e2e_replay.py", str(log))
    assert "targets differing: 0" in out
