"""The same log through chaincompd (recorded by lcm-logger) and through chaincomp_replay:
identical corrected values, bit for bit."""

import os
import signal
import subprocess
import sys
import tempfile
import time

import lcm_harness as h
from common import HERE, MACHINE, PARAMS
from lcm_harness import BUILD, ROOT, lcmt_axis_command  # noqa: F401

VENV_BIN = os.path.join(ROOT, ".venv", "bin")


def main(log_path: str) -> int:
    h.require_namespace()
    tmp = tempfile.mkdtemp()
    recorded = os.path.join(tmp, "daemon.lcmlog")
    replayed = os.path.join(tmp, "replay.lcmlog")
    config = f"{HERE}/config_test.yaml"
    logger = subprocess.Popen([os.path.join(VENV_BIN, "lcm-logger"), f"--lcm-url={h.URL}", "-c",
                               "CHAINCOMP_CORRECTED", "-f", recorded], stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL)
    daemon = h.start_daemon(MACHINE, PARAMS, config)
    listener = h.Listener()
    time.sleep(0.5)  # the logger subscribes
    pub = h.lcm.LCM(h.URL)
    commands = [e for e in h.lcm.EventLog(log_path, "r") if e.channel == "CHAINCOMP_COMMAND"]
    t0 = time.perf_counter()
    for i, e in enumerate(commands):
        h.pace(t0, i, 2000.0)
        pub.publish("CHAINCOMP_COMMAND", e.data)
    # lcm-logger loses the last few events of a stream on SIGINT: trail 50 more commands
    # (the last position held, later seq and utime) that the comparison ignores.
    last = h.lcmt_axis_command.decode(commands[-1].data)
    for k in range(1, 51):
        last.seq += 1
        last.utime += 1000
        pub.publish("CHAINCOMP_COMMAND", last.encode())
        time.sleep(0.001)
    listener.wait_for(lambda: len(listener.targets) >= len(commands) + 50, 10)
    time.sleep(0.5)
    logger.send_signal(signal.SIGINT)
    logger.wait(5)
    daemon.terminate()
    daemon.wait(5)
    listener.close()
    subprocess.run([os.path.join(BUILD, "bin", "chaincomp_replay"), "--machine", MACHINE, "--params", PARAMS,
                    "--config", config, "--in", log_path, "--out", replayed, "--quiet"], check=True,
                   stderr=subprocess.DEVNULL)

    def targets(path):
        out = {}
        for e in h.lcm.EventLog(path, "r"):
            if e.channel == "CHAINCOMP_CORRECTED":
                t = h.lcmt_corrected_target.decode(e.data)
                out[t.seq] = (tuple(t.axes), tuple(t.correction), t.residual_point, t.residual_direction,
                              t.flags, t.status)
        return out

    offline = targets(replayed)
    live = {seq: t for seq, t in targets(recorded).items() if seq in offline}
    print(f"daemon (lcm-logger): {len(live)} targets; replay: {len(offline)} targets; "
          f"missing from the daemon log: {sorted(set(offline) - set(live))[:10]}")
    assert len(live) == len(commands) == len(offline), (len(live), len(commands), len(offline))
    differing = [s for s in live if live[s] != offline[s]]
    print(f"targets differing: {len(differing)}")
    assert not differing, differing[:5]
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
