"""Helpers for end-to-end tests over LCM: run only inside a network namespace made by
netns.sh (udpm with ttl=0 on a loopback that carries multicast; never on the host)."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
BUILD = os.path.join(ROOT, "build")
sys.path.insert(0, os.path.join(BUILD, "lcmtypes"))

import lcm  # noqa: E402

sys.setswitchinterval(0.0002)  # let the listener thread take the GIL often
from chaincomp_lcm import (lcmt_axis_command, lcmt_chaincomp_control,  # noqa: E402,F401
                           lcmt_chaincomp_status, lcmt_corrected_target)

URL = "udpm://239.255.76.67:7667?ttl=0&recv_buf_size=2097152"


def require_namespace() -> None:
    # The harness refuses to run where multicast could leave the machine.
    if os.environ.get("CHAINCOMP_IN_NETNS") != "1":
        sys.exit("lcm_harness: run through tests/e2e/netns.sh (network namespace only)")


def start_daemon(machine: str, params: str, config: str, preload: bool = False,
                 model: str | None = None) -> subprocess.Popen:
    """chaincompd, once it says ready; the lines of a model build before that are printed."""
    env = dict(os.environ)
    if preload:
        env["LD_PRELOAD"] = os.path.join(BUILD, "runtime", "libchaincomp_alloc_counter.so")
    cmd = [os.path.join(BUILD, "bin", "chaincompd"), "--machine", machine, "--params", params, "--config", config]
    proc = subprocess.Popen(cmd + (["--model", model] if model else []), stderr=subprocess.PIPE, text=True, env=env)
    line = proc.stderr.readline()
    while line.startswith("chaincomp build:"):
        print(line, end="")
        line = proc.stderr.readline()
    if "ready" not in line:
        proc.kill()
        raise RuntimeError(f"chaincompd did not start: {line}{proc.stderr.read()}")
    return proc


class Listener:
    """Collects corrected targets and status messages on a thread of its own."""

    def __init__(self):
        self.lc = lcm.LCM(URL)
        self.targets: list[tuple[float, lcmt_corrected_target]] = []
        self.status: list[lcmt_chaincomp_status] = []
        # LCM drops beyond a subscription's queue capacity (default 30)
        self.lc.subscribe("CHAINCOMP_CORRECTED", self._on_target).set_queue_capacity(100000)
        self.lc.subscribe("CHAINCOMP_STATUS", self._on_status).set_queue_capacity(1000)
        self._stop = False
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _on_target(self, channel, data):
        self.targets.append((time.perf_counter(), lcmt_corrected_target.decode(data)))

    def _on_status(self, channel, data):
        self.status.append(lcmt_chaincomp_status.decode(data))

    def _run(self):
        while not self._stop:
            self.lc.handle_timeout(50)

    def wait_for(self, predicate, timeout: float = 10.0) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if predicate():
                return True
            time.sleep(0.01)
        return predicate()

    def close(self):
        self._stop = True
        self._thread.join()


def command(seq: int, axes, machine: str = "five_axis_ac", utime: int | None = None) -> bytes:
    msg = lcmt_axis_command()
    msg.utime = int(time.time() * 1e6) if utime is None else utime
    msg.seq = seq
    msg.machine = machine
    msg.num_axes = len(axes)
    msg.axes = list(axes) + [0.0] * (8 - len(axes))
    return msg.encode()


def control(enable: bool) -> bytes:
    msg = lcmt_chaincomp_control()
    msg.utime = int(time.time() * 1e6)
    msg.enable = enable
    return msg.encode()


def pace(t0: float, i: int, rate_hz: float) -> None:
    """Sleep until the i-th slot of a stream at rate_hz started at t0. Sleeping (not
    spinning) leaves the CPU and the GIL to the daemon and the listener thread; above 1 kHz
    the stream goes out in groups once per millisecond."""
    due = t0 + i / rate_hz
    delay = due - time.perf_counter()
    if delay > 0:
        time.sleep(delay)
