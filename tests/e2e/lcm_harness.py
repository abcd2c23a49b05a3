"""Helpers for end-to-end tests over LCM: run only inside a network namespace made by
netns.sh (udpm with ttl=0 on a loopback that carries multicast; never on the host)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
BUILD = os.path.join(ROOT, "build")
# CHAINCOMP_E2E_DAEMON runs the scenarios with another build's daemon (ThreadSanitizer's: tools/test)
DAEMON = os.environ.get("CHAINCOMP_E2E_DAEMON") or os.path.join(BUILD, "bin", "chaincompd")
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
                 model: str | None = None, extra: tuple[str, ...] = (),
                 wrapper: tuple[str, ...] = ()) -> subprocess.Popen:
    """chaincompd (under `wrapper`, e.g. valgrind, when given), once it says ready; the lines
    of a model build (and warnings) before that are printed (the warnings kept in
    proc.warnings); its instance id is proc.instance."""
    env = dict(os.environ)
    if preload:
        env["LD_PRELOAD"] = os.path.join(BUILD, "runtime", "libchaincomp_alloc_counter.so")
    cmd = [DAEMON, "--machine", machine, "--params", params, "--config", config]
    proc = subprocess.Popen(list(wrapper) + cmd + (["--model", model] if model else []) + list(extra),
                            stderr=subprocess.PIPE,
                            text=True, env=env)
    line = proc.stderr.readline()
    proc.warnings = []
    # before the ready line: a model build's lines, warnings (LCM's own run over lines)
    while line and not line.startswith("chaincompd: error") and not line.rstrip().endswith("; ready"):
        print(line, end="")
        if line.startswith("chaincompd: warning:"):
            proc.warnings.append(line.strip())
        line = proc.stderr.readline()
    if "ready" not in line:
        proc.kill()
        raise RuntimeError(f"chaincompd did not start: {line}{proc.stderr.read()}")
    proc.instance = int(line.split("instance ")[1].split(";")[0], 16)
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


def control(enable: bool, reset: bool = False) -> bytes:
    msg = lcmt_chaincomp_control()
    msg.utime = int(time.time() * 1e6)
    msg.enable = enable
    msg.reset = reset
    return msg.encode()


def warm_backlog(daemon: subprocess.Popen, publish, first: int, count: int = 1000) -> None:
    """Warm-up with a backlog deeper than a loaded machine's stalls (tens of ms at 10 kHz):
    the daemon stopped while `count` commands arrive (publish(i) for i in first..first+count-1),
    then resumed. LCM grows its receive ring to the deepest backlog it has held (its own
    targets heard back queue there too): here, not in the steady state."""
    daemon.send_signal(signal.SIGSTOP)
    try:
        for i in range(first, first + count):
            publish(i)
        time.sleep(0.02)
    finally:
        daemon.send_signal(signal.SIGCONT)


def final_status(listener: "Listener", daemon: subprocess.Popen) -> lcmt_chaincomp_status:
    """The status the daemon published at exit (it must have published one)."""
    listener.wait_for(lambda: any(s.final and s.instance_id == daemon.instance for s in listener.status), 3)
    finals = [s for s in listener.status if s.final and s.instance_id == daemon.instance]
    assert finals, f"no final status (daemon exit {daemon.returncode}): {daemon.stderr.read()}"
    return finals[-1]


def print_losses(s: lcmt_chaincomp_status) -> None:
    """What the daemon says about loss: commands never received, kernel drops, its own
    targets heard back."""
    print(f"daemon {s.instance_id:016x}: received {s.received}, published {s.published}, seq gaps {s.seq_gaps} "
          f"({s.seq_missing} missing), kernel drops {s.kernel_drops} (buffer {s.recv_buf_bytes} B), "
          f"own targets heard back {s.own_targets_heard}, foreign targets {s.foreign_targets}")


class LoggedPublisher:
    """Publishes on the bus and writes the same events, in the same order, to a log that
    chaincomp_replay can take."""

    def __init__(self, log_path: str):
        self.lc = lcm.LCM(URL)
        self.log = lcm.EventLog(log_path, "w", overwrite=True)

    def publish(self, channel: str, data: bytes) -> None:
        self.lc.publish(channel, data)
        self.log.write_event(int(time.time() * 1e6), channel, data)

    def close(self) -> None:
        self.log.close()


def replay(machine: str, params: str, config: str, log_path: str, out_path: str, *extra: str) -> dict:
    """chaincomp_replay of a log (extra options: --thermal T.yaml): its targets by seq."""
    subprocess.run([os.path.join(BUILD, "bin", "chaincomp_replay"), "--machine", machine, "--params", params,
                    "--config", config, "--in", log_path, "--out", out_path, "--quiet", *extra], check=True,
                   stderr=subprocess.DEVNULL)
    return {t.seq: t for t in (lcmt_corrected_target.decode(e.data) for e in lcm.EventLog(out_path, "r")
                               if e.channel == "CHAINCOMP_CORRECTED")}


def target_key(t: lcmt_corrected_target) -> tuple:
    """What a target says: equal keys are the same target bit for bit."""
    return (tuple(t.axes), tuple(t.correction), t.residual_point, t.residual_direction, t.flags, t.status)


def pace(t0: float, i: int, rate_hz: float) -> None:
    """Sleep until the i-th slot of a stream at rate_hz started at t0. Sleeping (not
    spinning) leaves the CPU and the GIL to the daemon and the listener thread; above 1 kHz
    the stream goes out in groups once per millisecond."""
    due = t0 + i / rate_hz
    delay = due - time.perf_counter()
    if delay > 0:
        time.sleep(delay)
