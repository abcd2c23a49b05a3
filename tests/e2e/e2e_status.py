"""`chaincomp status --once` against two daemons for one machine (twins, so each also counts
the other's targets as foreign):
  live   while a stream runs, each daemon's last target as status shows it is one the
         harness heard too, its correction converted by hand (mm -> µm, deg -> arcsec), and
         the command's age is that of a command just sent;
  final  after the stream (with commands refused for a wrong machine and a duplicate seq),
         status's counters, rejections by reason and latency equal each daemon's final
         status; the text view names both daemons and the reasons."""

import json
import os
import subprocess
import sys
import threading
import time

import lcm_harness as h
from common import HERE, MACHINE, PARAMS, toolpath

CHAINCOMP = os.path.join(h.ROOT, ".venv", "bin", "chaincomp")
COUNTERS = ("received", "published", "unpublished", "clamped", "held_back", "clamped_input", "seq_gaps",
            "seq_missing", "queue_dropped", "stream_restarts", "resets", "kernel_drops", "own_targets_heard",
            "foreign_targets")
REASONS = ("undecodable", "wrong machine", "wrong axis count", "non-finite", "out of limits",
           "step too large", "duplicate seq", "out-of-order seq", "compensation failed")
AXIS_UNITS = (("X", 1000.0, "um"), ("Y", 1000.0, "um"), ("Z", 1000.0, "um"),
              ("Ap", 3600.0, "arcsec"), ("Cp", 3600.0, "arcsec"))   # five_axis_ac: mm, mm, mm, deg, deg


def status(*args, timeout="0.5") -> subprocess.CompletedProcess:
    return subprocess.run([CHAINCOMP, "status", "--once", "--url", h.URL, "--timeout", timeout, *args],
                          capture_output=True, text=True, timeout=30)


def main() -> int:
    h.require_namespace()
    daemons = [h.start_daemon(MACHINE, PARAMS, f"{HERE}/config_test.yaml") for _ in range(2)]
    listener = h.Listener()
    pub = h.lcm.LCM(h.URL)
    path = toolpath(4000)
    seq = 0

    # live: a 200 Hz stream with real timestamps, running for the whole of status's listening
    stop = threading.Event()
    sent_at = {}

    def stream():
        nonlocal seq
        while not stop.is_set():
            seq += 1
            sent_at[seq] = time.time()
            pub.publish("CHAINCOMP_COMMAND", h.command(seq, path[seq % 4000]))
            time.sleep(0.005)

    thread = threading.Thread(target=stream)
    thread.start()
    time.sleep(0.2)
    live = status("--format", "json", timeout="1.0")
    stop.set()
    thread.join()
    assert live.returncode == 0, live.stderr
    doc = json.loads(live.stdout)
    by_instance = {int(d["instance"], 16): d for d in doc["daemons"]}
    assert sorted(by_instance) == sorted(d.instance for d in daemons), (by_instance.keys(), daemons)
    heard = {(t.instance_id, t.seq): t for _, t in listener.targets}
    for d in daemons:
        got = by_instance[d.instance]
        assert got["machine"] == "five_axis_ac" and got["state"] == "enabled" and not got["final"]
        last = got["last_target"]
        t = heard[(d.instance, last["seq"])]
        for shown, corr, (axis, scale, unit) in zip(last["correction"], t.correction, AXIS_UNITS):
            assert shown["axis"] == axis and shown["unit"] == unit, shown
            assert abs(shown["value"] - corr * scale) <= 1e-9 * max(1.0, abs(corr * scale)), (shown, corr)
        assert any(abs(a["value"]) > 0.01 for a in last["correction"]), last   # the demo params do correct
        # the last command shown is one of the last sent (status listened to the end of its window)
        # (seq goes on while status loads the machine file after its window: 400 is 2 s of stream)
        assert last["seq"] > seq - 400, (last["seq"], seq)
        assert 0 <= last["command_age_s"] < 1, last
        print(f"live: {d.instance:016x} last seq {last['seq']} of {seq} sent, correction "
              + " ".join(f"{a['axis']} {a['value']:+.3f} {a['unit']}" for a in last["correction"])
              + f", command {last['command_age_s']:.3f} s old")

    # final: commands refused for reasons status must count apart
    pub.publish("CHAINCOMP_COMMAND", h.command(seq + 1, path[0], machine="vmc_xyz"))
    pub.publish("CHAINCOMP_COMMAND", h.command(seq + 1, path[0], machine="vmc_xyz"))
    pub.publish("CHAINCOMP_COMMAND", h.command(seq, path[seq % 4000]))   # the last seq again
    expected = {"received": seq + 3, "published": seq}

    def settled():   # every daemon's status has counted every command and its targets heard back
        last = {}
        for s in listener.status:
            last[s.instance_id] = s
        return all(d.instance in last and last[d.instance].received == seq + 3
                   and last[d.instance].own_targets_heard == seq and last[d.instance].foreign_targets == seq
                   for d in daemons)
    assert listener.wait_for(settled, 10), "the daemons' counters did not settle"
    quiet = status("--format", "json")
    text = status()
    for d in daemons:
        d.terminate()
        d.wait(5)
    finals = {d.instance: h.final_status(listener, d) for d in daemons}
    listener.close()
    assert quiet.returncode == 0 and text.returncode == 0, quiet.stderr + text.stderr
    shown = {int(d["instance"], 16): d for d in json.loads(quiet.stdout)["daemons"]}
    for instance, final in finals.items():
        h.print_losses(final)
        got = shown[instance]
        assert got["counters"] == {k: getattr(final, k) for k in COUNTERS}, got["counters"]
        assert got["receipt_latency_ns"] == {"p50": final.receipt_p50_ns, "p99": final.receipt_p99_ns,
                                             "max": final.receipt_max_ns}
        # waiting included: never less than the compute time of the same commands' window
        assert final.receipt_p50_ns >= final.latency_p50_ns > 0
        assert got["rejected"] == dict(zip(REASONS, final.rejected)), got["rejected"]
        assert got["latency_ns"] == {"window": final.window, "p50": final.latency_p50_ns, "p99": final.latency_p99_ns,
                                     "p999": final.latency_p999_ns, "max": final.latency_max_ns}
        # and the counts are the ones this scenario caused
        assert final.received == expected["received"] and final.published == expected["published"]
        assert final.rejected[1] == 2 and final.rejected[6] == 1 and sum(final.rejected) == 3
        assert final.foreign_instance in finals and final.foreign_instance != instance
        assert abs(got["status_period_s"] - 0.05) < 0.025, got["status_period_s"]   # config_test.yaml's
        print(f"final: {instance:016x} status --once shows the final counters: {got['counters']}")
        assert f"instance {instance:016x}  enabled" in text.stdout, text.stdout
    assert text.stdout.startswith(f"2 chaincompd on {h.URL}\n"), text.stdout
    assert text.stdout.count("rejected 3 (wrong machine 2, duplicate seq 1)") == 2, text.stdout
    print(text.stdout)
    return 0


if __name__ == "__main__":
    sys.exit(main())
