"""The same log through chaincompd (its targets recorded off the bus) and through
chaincomp_replay: identical corrected values, bit for bit.

The daemon's targets are recorded by this test's listener (LCM queue of 10^5 messages), not
by lcm-logger: beside a CPU hog lcm-logger recorded 1988 and 1996 of 2000 while no UDP socket
in the namespace had dropped one (/proc/net/udp) and the daemon had published every target
and heard every one back; the loss is inside lcm-logger's process (LCM's per-subscription
queue holds 30 messages by default)."""

import os
import sys
import tempfile
import time

import lcm_harness as h
from common import HERE, MACHINE, PARAMS


def main(log_path: str) -> int:
    h.require_namespace()
    tmp = tempfile.mkdtemp()
    replayed = os.path.join(tmp, "replay.lcmlog")
    config = f"{HERE}/config_test.yaml"
    daemon = h.start_daemon(MACHINE, PARAMS, config)
    listener = h.Listener()
    pub = h.lcm.LCM(h.URL)
    commands = [e for e in h.lcm.EventLog(log_path, "r") if e.channel == "CHAINCOMP_COMMAND"]
    t0 = time.perf_counter()
    for i, e in enumerate(commands):
        h.pace(t0, i, 2000.0)
        pub.publish("CHAINCOMP_COMMAND", e.data)
    listener.wait_for(lambda: len(listener.targets) >= len(commands), 10)
    daemon.terminate()
    daemon.wait(5)
    final = h.final_status(listener, daemon)
    listener.close()
    h.print_losses(final)
    offline = {}
    for seq, t in h.replay(MACHINE, PARAMS, config, log_path, replayed).items():
        assert t.machine == "five_axis_ac" and t.instance_id == 0
        offline[seq] = h.target_key(t)
    live = {t.seq: h.target_key(t) for _, t in listener.targets if t.instance_id == daemon.instance}
    print(f"daemon (off the bus): {len(live)} targets; replay: {len(offline)} targets; "
          f"missing off the bus: {sorted(set(offline) - set(live))[:10]}")
    assert len(live) == len(commands) == len(offline), (len(live), len(commands), len(offline))
    differing = [s for s in live if live[s] != offline[s]]
    print(f"targets differing: {len(differing)}")
    assert not differing, differing[:5]
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
