"""Hostile streams and a crowded bus, each with its exact counters:
  lockout  one command with seq 2^63-1, then the real stream: followed again after
           kRestartRun (5) commands; a CNC restart (seq from 1) likewise; a reset on the
           control channel at once; machine names with a NUL inside or empty are refused;
  twins    a second daemon for the same machine: each reports the other on status and stderr;
  tiny     recv_buf_size 2048 and a burst: the loss is provoked, and the daemon's counters
           explain it exactly (commands missing = sent - received; kernel drops = those
           commands + its own targets not heard back);
  capped   recv_buf_size beyond net.core.rmem_max: one warning, and status shows what was obtained."""

import os
import sys
import tempfile
import time

import lcm_harness as h
from common import HERE, MACHINE, PARAMS, toolpath

RESTART_RUN = 5  # kRestartRun in compensator.hpp
REASONS = ["undecodable", "wrong_machine", "wrong_axis_count", "non_finite", "out_of_limits",
           "step_too_large", "duplicate_seq", "out_of_order_seq", "compensation_failed"]
INT64_MAX = 2**63 - 1


def lockout() -> None:
    daemon = h.start_daemon(MACHINE, PARAMS, f"{HERE}/config_test.yaml")
    listener = h.Listener()
    pub = h.lcm.LCM(h.URL)
    path = toolpath(2000)
    utime = 1_000_000

    def send(seq, i, machine="five_axis_ac"):
        nonlocal utime
        utime += 1000
        pub.publish("CHAINCOMP_COMMAND", h.command(seq, path[i % 2000], machine=machine, utime=utime))
        time.sleep(0.0005)

    for i in range(100):
        send(i + 1, i)
    send(INT64_MAX, 100)          # accepted: a valid command, seq far ahead
    for i in range(101, 301):     # the real stream goes on: 4 refused, then followed
        send(i, i)
    for i in range(200):          # the CNC restarts its numbering: 4 refused, then followed
        send(i + 1, 301 + i)
    pub.publish("CHAINCOMP_CONTROL", h.control(True, reset=True))
    time.sleep(0.05)
    for i in range(100):          # after a reset: seq 1 again, accepted at once
        send(i + 1, 501 + i)
    send(101, 601, machine="five_axis_ac\0garbage")
    send(101, 601, machine="")
    send(101, 601)
    expected_published = 100 + 1 + (200 - 4) + (200 - 4) + 100 + 1
    listener.wait_for(lambda: len(listener.targets) >= expected_published, 10)
    time.sleep(0.1)
    daemon.terminate()
    daemon.wait(5)
    final = h.final_status(listener, daemon)
    listener.close()
    rejected = {k: v for k, v in zip(REASONS, final.rejected) if v}
    print(f"lockout: published {final.published} of {final.received}, rejected {rejected}, restarts "
          f"{final.stream_restarts}, resets {final.resets}, gaps {final.seq_gaps} ({final.seq_missing} missing)")
    assert final.published == expected_published == len(listener.targets)
    assert rejected == {"out_of_order_seq": 2 * (RESTART_RUN - 1), "wrong_machine": 2}, rejected
    assert final.stream_restarts == 2 and final.resets == 1
    # the one gap is the jump to 2^63-1 (seq 101 .. 2^63-2 never came)
    assert final.seq_gaps == 1 and final.seq_missing == INT64_MAX - 101
    seqs = [t.seq for _, t in listener.targets]
    assert seqs[99:102] == [100, INT64_MAX, 105]
    assert seqs[101 + 196] == 5 and seqs[101 + 2 * 196] == 1  # restart at seq 5; after the reset, seq 1


def twins() -> None:
    first = h.start_daemon(MACHINE, PARAMS, f"{HERE}/config_test.yaml")
    second = h.start_daemon(MACHINE, PARAMS, f"{HERE}/config_test.yaml")
    listener = h.Listener()
    pub = h.lcm.LCM(h.URL)
    path = toolpath(1000)
    for i in range(50):
        pub.publish("CHAINCOMP_COMMAND", h.command(i + 1, path[i]))
        time.sleep(0.001)
    listener.wait_for(lambda: len(listener.targets) >= 100, 10)
    time.sleep(0.1)
    for d in (first, second):
        d.terminate()
        d.wait(5)
    finals = [h.final_status(listener, d) for d in (first, second)]
    listener.close()
    errs = [d.stderr.read() for d in (first, second)]
    for me, other, final, err in ((first, second, finals[0], errs[0]), (second, first, finals[1], errs[1])):
        print(f"twins: {me.instance:016x} heard {final.foreign_targets} targets of {final.foreign_instance:016x}")
        assert final.published == 50 and final.own_targets_heard == 50
        assert final.foreign_targets == 50 and final.foreign_instance == other.instance
        assert err.count(f"another daemon (instance {other.instance:016x}) publishes targets for five_axis_ac") == 1
    by_instance = {}
    for _, t in listener.targets:
        assert t.machine == "five_axis_ac"
        by_instance.setdefault(t.instance_id, []).append(t.seq)
    assert by_instance == {first.instance: list(range(1, 51)), second.instance: list(range(1, 51))}


def tiny() -> None:
    config = os.path.join(tempfile.mkdtemp(), "tiny.yaml")
    with open(f"{HERE}/config_test.yaml") as f:
        text = f.read().replace("status_period: 0.05", "status_period: 60")
    with open(config, "w") as f:
        f.write(text + "recv_buf_size: 2048\n")
    daemon = h.start_daemon(MACHINE, PARAMS, config)
    listener = h.Listener()
    pub = h.lcm.LCM(h.URL)
    axes = toolpath(1000)[0]  # one position: a gap never makes a step too large
    burst, tail = 5000, 20
    for seq in range(1, burst + 1):  # as fast as Python publishes: the tiny buffer overflows
        pub.publish("CHAINCOMP_COMMAND", h.command(seq, axes))
    for seq in range(burst + 1, burst + tail + 1):  # slowly: the last seq arrives, so every loss is a gap
        time.sleep(0.01)
        pub.publish("CHAINCOMP_COMMAND", h.command(seq, axes))
    time.sleep(0.5)
    daemon.terminate()
    daemon.wait(5)
    s = h.final_status(listener, daemon)
    listener.close()
    sent = burst + tail
    h.print_losses(s)
    assert s.recv_buf_bytes == 2 * 2048  # the kernel doubles what is asked
    assert s.received + s.seq_missing == sent and s.published == s.received and sum(s.rejected) == 0
    assert s.seq_missing > 0, "no loss provoked: the test shows nothing"
    assert s.kernel_drops == s.seq_missing + (s.published - s.own_targets_heard), "drops not explained"


def capped() -> None:
    with open("/proc/sys/net/core/rmem_max") as f:
        rmem_max = int(f.read())
    config = os.path.join(tempfile.mkdtemp(), "capped.yaml")
    with open(config, "w") as f:
        f.write(f'lcm_url: "udpm://239.255.76.67:7667?ttl=0"\nrecv_buf_size: {4 * rmem_max}\n')
    daemon = h.start_daemon(MACHINE, PARAMS, config)
    listener = h.Listener()
    daemon.terminate()
    daemon.wait(5)
    s = h.final_status(listener, daemon)
    listener.close()
    print(f"capped: asked {4 * rmem_max}, obtained {s.recv_buf_bytes // 2} (net.core.rmem_max {rmem_max})")
    assert s.recv_buf_bytes == 2 * rmem_max
    assert daemon.warnings == [f"chaincompd: warning: socket receive buffer {rmem_max} bytes, not the "
                               f"{4 * rmem_max} asked (recv_buf_size; raise net.core.rmem_max); continuing"]


def main() -> int:
    h.require_namespace()
    t0 = time.perf_counter()
    for scenario in (lockout, twins, tiny, capped):
        scenario()
        print(f"{scenario.__name__}: {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
