"""The whole thermal loop through chaincompd: a thermal model fitted (chaincomp thermal fit) to
a simulated warm-up, then a held-out cycle the fit never saw streamed to the daemon as
temperature readings and commands. The tool's thermal drift at the daemon's targets, by the
exact chain with the true error values, against the drift a compensation without the thermal
model leaves (chaincomp_replay of the same events without --thermal): at most 30 % of it.
chaincomp_replay --thermal reproduces the daemon's targets bit for bit."""

import os
import subprocess
import sys
import tempfile
import time

import numpy as np

import lcm_harness as h
from common import HERE, MACHINE, PARAMS, exact_errors, toolpath
from lcm_harness import ROOT
from chaincomp_lcm import lcmt_temperatures

# a plausible thermal model of five_axis_ac: the spindle's growth and the column's
TRUE = """machine: five_axis_ac
errors:
  EZZ:
    unit: um
    terms:
      - {sensor: T_spindle, gain: -1.5, time_constant: 900}
      - {sensor: T_column, gain: 0.6, time_constant: 3600}
  EYZ:
    unit: um
    terms:
      - {sensor: T_column, gain: -0.8, time_constant: 2400}
"""
RATE = 0.2   # readings per second in the logs


def chaincomp(*args):
    subprocess.run([sys.executable, "-m", "chaincomp.cli.main", *map(str, args)], check=True, cwd=ROOT,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def read_log(path):
    with open(path) as f:
        lines = [line for line in f if not line.startswith("#")]
    header = [c.split(" [")[0] for c in lines[0].strip().split(",")]
    data = np.array([[float(x) for x in line.split(",")] for line in lines[1:]])
    return {name: data[:, k] for k, name in enumerate(header)}


def readings(t_us, temps) -> bytes:
    m = lcmt_temperatures()
    m.utime, m.machine = t_us, ""
    m.num_values = len(temps)
    m.names = list(temps)
    m.values = [float(v) for v in temps.values()]
    return m.encode()


def main() -> int:
    h.require_namespace()
    tmp = tempfile.mkdtemp()
    true, warm, held, fitted = (os.path.join(tmp, n) for n in ("true.yaml", "warm.csv", "held.csv", "fitted.yaml"))
    with open(true, "w") as f:
        f.write(TRUE)
    chaincomp("simulate-thermal", MACHINE, "--truth", true, "-o", warm, "--rate", RATE)
    chaincomp("simulate-thermal", MACHINE, "--truth", true, "-o", held, "--rate", RATE, "--cycle", "varied",
              "--seed", "2", "--drift-noise", "0")
    chaincomp("thermal", "fit", MACHINE, warm, "-o", fitted)
    log = read_log(held)
    sensors = [k for k in log if k.startswith("T_")]
    n = len(log["time"])
    config = f"{HERE}/config_test.yaml"
    daemon = h.start_daemon(MACHINE, PARAMS, config, extra=("--thermal", fitted))
    listener = h.Listener()
    events = os.path.join(tmp, "events.lcmlog")
    pub = h.LoggedPublisher(events)
    send = pub.publish

    path = toolpath(n)
    t0 = time.perf_counter()
    base_us = 1_000_000_000
    for k in range(n):
        h.pace(t0, k, 2000.0)   # the cycle's hours in seconds: the lags run on the readings' own time
        t_us = base_us + int(round(log["time"][k] * 1e6))
        send("CHAINCOMP_TEMPERATURES", readings(t_us, {s: log[s][k] for s in sensors}))
        send("CHAINCOMP_COMMAND", h.command(k + 1, path[k], utime=t_us + 1000))
    pub.close()
    listener.wait_for(lambda: len([t for _, t in listener.targets if t.instance_id == daemon.instance]) >= n, 10)
    daemon.terminate()
    daemon.wait(5)
    final = h.final_status(listener, daemon)
    listener.close()
    h.print_losses(final)
    print(f"readings: received {final.readings_received}, refused {list(final.readings_refused)}; params version "
          f"{final.params_version}, refused {list(final.params_refused)}")
    targets = {t.seq: t for _, t in listener.targets if t.instance_id == daemon.instance}
    assert len(targets) == n and sum(final.rejected) == 0
    assert final.readings_received == n and sum(final.readings_refused) == 0
    assert final.params_version == n   # every reading applied (5 s of command time apart)

    def replay(*extra):
        return h.replay(MACHINE, PARAMS, config, events, os.path.join(tmp, f"replay{len(extra)}.lcmlog"), *extra)

    seqs = range(1, n + 1)
    offline = replay("--thermal", fitted)
    differing = [s for s in seqs if h.target_key(offline[s]) != h.target_key(targets[s])]
    print(f"replay --thermal: {len(offline)} targets, differing from the daemon's: {len(differing)}")
    assert not differing, differing[:5]
    geometric = replay()   # the same events, compensated without the thermal model
    truth = {"EZZ": log["EZZ"] * 1e-3, "EYZ": log["EYZ"] * 1e-3}   # the true thermal values, mm
    with_model, _ = exact_errors(path, np.array([targets[s].axes[:5] for s in seqs]), added=truth)
    without, _ = exact_errors(path, np.array([geometric[s].axes[:5] for s in seqs]), added=truth)
    share = with_model.max() / without.max()
    print(f"held-out cycle ({n} readings over {log['time'][-1] / 3600:.1f} h): thermal drift of the tool "
          f"{1e3 * without.max():.2f} um max ({1e3 * np.sqrt(np.mean(without ** 2)):.2f} um RMS) without the model, "
          f"{1e3 * with_model.max():.3f} um max ({1e3 * np.sqrt(np.mean(with_model ** 2)):.3f} um RMS) with it: "
          f"{100 * share:.1f} % left ({100 * (1 - share):.1f} % reduction)")
    assert share <= 0.3
    return 0


if __name__ == "__main__":
    sys.exit(main())
