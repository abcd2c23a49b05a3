"""One bundled machine through chaincompd: publish every command of a log (from
chaincomp simulate-log) at 2 kHz, collect the corrected targets and write them as JSON
(floats written exactly) for the caller to compare with chaincomp replay's.

    netns.sh python e2e_machine.py MACHINE.yaml PARAMS.yaml CONFIG.yaml IN.lcmlog OUT.json
"""

import json
import sys
import time

import lcm_harness as h


def main(machine: str, params: str, config: str, log: str, out: str) -> int:
    h.require_namespace()
    commands = [e.data for e in h.lcm.EventLog(log, "r") if e.channel == "CHAINCOMP_COMMAND"]
    daemon = h.start_daemon(machine, params, config)
    listener = h.Listener()
    pub = h.lcm.LCM(h.URL)
    t0 = time.perf_counter()
    for i, data in enumerate(commands):
        h.pace(t0, i, 2000.0)
        pub.publish("CHAINCOMP_COMMAND", data)
    ok = listener.wait_for(lambda: len(listener.targets) >= len(commands), 10)
    daemon.terminate()
    daemon.wait(5)
    listener.wait_for(lambda: any(s.final for s in listener.status), 3)
    listener.close()
    final = [s for s in listener.status if s.final]
    with open(out, "w") as f:
        json.dump({"sent": len(commands), "complete": ok,
                   "received": final[-1].received if final else None,
                   "rejected": list(final[-1].rejected) if final else None,
                   "targets": [{"seq": t.seq, "axes": list(t.axes), "status": t.status, "flags": t.flags}
                               for _, t in listener.targets]}, f)
    print(f"{machine}: sent {len(commands)}, received {len(listener.targets)} targets")
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:6]))
