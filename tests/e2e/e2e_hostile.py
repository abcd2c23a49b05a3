"""Hostile streams and a crowded bus, each with its exact counters:
  lockout  one command with seq 2^63-1 mid-stream: refused (more than 2^32 ahead), the real
           stream goes on; a CNC restart (seq from 1): followed again after kRestartRun (5)
           commands; a reset on the control channel at once; machine names with a NUL inside
           or empty are refused;
  streams  the sequences of issue 39 that locked out params updates and temperature readings:
           an update with seq 2^63-1, a PLC restarting its numbering, a command at utime
           INT64_MIN, readings a year ahead and at 2^63-1, updates while no command comes, and a
           reset that must clear every stream: each stream followed again within its restart run;
  same     two starts of the daemon given the same messages publish the same status bytes
           (but for the clock, the instance and the measured latency): no process memory;
  memcheck the daemon under Valgrind's memcheck through hostile messages of every stream: no
           uninitialised byte sent, no invalid read or write;
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
from chaincomp_lcm import lcmt_params_update, lcmt_temperatures
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
    send(INT64_MAX, 100)          # refused: more than 2^32 ahead, no gap counted
    for i in range(101, 301):     # the real stream goes on at once
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
    expected_published = 100 + 200 + (200 - 4) + 100 + 1
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
    assert rejected == {"out_of_order_seq": 1 + (RESTART_RUN - 1), "wrong_machine": 2}, rejected
    assert final.stream_restarts == 1 and final.resets == 1
    assert final.seq_gaps == 0 and final.seq_missing == 0   # 2^63-1 is no gap of lost commands
    seqs = [t.seq for _, t in listener.targets]
    assert seqs[99:101] == [100, 101]
    assert seqs[300] == 5 and seqs[300 + 196] == 1  # restart at seq 5; after the reset, seq 1


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


THERMAL = """machine: five_axis_ac
errors:
  EXX:
    unit: um
    terms:
      - {sensor: T_a, gain: 1.0}
"""
PARAMS_REASONS = ("undecodable", "wrong machine", "another instance", "bad count", "unknown name", "not an error",
                  "repeated name", "non-finite", "out of bound", "stale seq", "too frequent")
READING_REASONS = ("undecodable", "wrong machine", "bad value", "time not increasing")


class Bus:
    """One publisher of every input stream, commands along the toolpath at about 1 kHz
    (1 ms of command time each)."""

    def __init__(self):
        self.lc = h.lcm.LCM(h.URL)
        self.path = toolpath(2000)
        self.seq, self.utime = 0, 1_000_000

    def commands(self, n: int) -> None:
        for _ in range(n):
            self.seq += 1
            self.utime += 1000
            self.lc.publish("CHAINCOMP_COMMAND", h.command(self.seq, self.path[self.seq % 2000], utime=self.utime))
            time.sleep(0.0005)
        time.sleep(0.01)

    def command_at(self, utime: int) -> None:
        self.seq += 1
        self.lc.publish("CHAINCOMP_COMMAND", h.command(self.seq, self.path[self.seq % 2000], utime=utime))
        time.sleep(0.01)

    def update(self, seq: int, exx: float = 1e-3) -> None:
        m = lcmt_params_update()
        m.utime, m.seq, m.machine, m.instance_id = 0, seq, "five_axis_ac", 0
        m.num_values, m.names, m.values = 1, ["EXX"], [exx]
        self.lc.publish("CHAINCOMP_PARAMS", m.encode())
        time.sleep(0.02)

    def readings(self, utime: int, t_a: float = 25.0) -> None:
        m = lcmt_temperatures()
        m.utime, m.machine, m.num_values, m.names, m.values = utime, "", 1, ["T_a"], [t_a]
        self.lc.publish("CHAINCOMP_TEMPERATURES", m.encode())
        time.sleep(0.02)

    def reset(self) -> None:
        self.lc.publish("CHAINCOMP_CONTROL", h.control(True, reset=True))
        time.sleep(0.02)


def streams_config(tmp: str) -> tuple[str, str]:
    """config_test.yaml with the default min_interval (10 ms), and a thermal model of one sensor."""
    config, thermal = os.path.join(tmp, "streams.yaml"), os.path.join(tmp, "thermal.yaml")
    with open(f"{HERE}/config_test.yaml") as f:
        text = f.read().replace("params_updates: {min_interval: 0.0}", "params_updates: {min_interval: 0.01}")
    with open(config, "w") as f:
        f.write(text)
    with open(thermal, "w") as f:
        f.write(THERMAL)
    return config, thermal


def streams() -> None:
    config, thermal = streams_config(tempfile.mkdtemp())
    daemon = h.start_daemon(MACHINE, PARAMS, config, extra=("--thermal", thermal))
    listener = h.Listener()
    bus = Bus()
    s, year = 1_000_000, 365 * 86400 * 1_000_000
    bus.commands(20)
    bus.update(1000)                 # applied (1)
    bus.commands(20)
    bus.update(INT64_MAX)            # refused: stale seq (more than 2^32 ahead)
    bus.update(1001)                 # applied (2): the stream goes on
    for k in range(1, 6):            # the PLC restarts at 1: 1..4 refused, 5 applied (3)
        bus.commands(20)
        bus.update(k)
    bus.commands(20)
    bus.update(6)                    # applied (4)
    bus.command_at(-2**63)           # a command at utime INT64_MIN, accepted
    bus.update(7)                    # applied (5)
    bus.commands(20)
    bus.update(8)                    # applied (6): INT64_MIN's distance must not overflow into "too soon"
    bus.commands(20)
    bus.readings(10 * s)             # the thermal model's first values, applied (7)
    bus.readings(10 * s + year)      # refused: a year ahead
    bus.readings(INT64_MAX)          # refused
    bus.commands(20)
    bus.readings(11 * s)             # applied (8): the sensor's stream goes on
    time.sleep(1.2)                  # no command for more than a second
    bus.readings(12 * s)             # applied (9), and again 20 ms of receipt later (10)
    bus.readings(13 * s)
    bus.update(100)                  # applied (11)
    bus.reset()                      # every stream new
    time.sleep(0.02)
    bus.update(1)                    # applied at once (12)
    bus.readings(1 * s)              # taken at once, applied 20 ms of receipt later (13)
    seq_before = bus.seq
    bus.seq = 0
    bus.commands(5)                  # seq 1..5 after the reset: taken at once
    time.sleep(0.1)
    daemon.terminate()
    daemon.wait(5)
    final = h.final_status(listener, daemon)
    listener.close()
    refused = {k: v for k, v in zip(PARAMS_REASONS, final.params_refused) if v}
    readings = {k: v for k, v in zip(READING_REASONS, final.readings_refused) if v}
    print(f"streams: params version {final.params_version} of {final.params_received} received, refused {refused}; "
          f"readings {final.readings_received}, refused {readings}; commands published {final.published} of "
          f"{final.received}, resets {final.resets}")
    assert final.params_version == 13, final.params_version
    assert refused == {"stale seq": 1 + 4}, refused
    assert final.readings_received == 7 and readings == {"time not increasing": 2}, readings
    assert final.params_received == 13 + 5 and final.params_seq == 1
    assert final.received == seq_before + 5 and final.published == final.received and final.resets == 1


def masked_status(final) -> bytes:
    """The status message without what differs between two runs by design: the clock, the
    instance and the latency measured."""
    final.utime = final.uptime_us = final.instance_id = 0
    final.latency_p50_ns = final.latency_p99_ns = final.latency_p999_ns = final.latency_max_ns = 0
    final.receipt_p50_ns = final.receipt_p99_ns = final.receipt_max_ns = 0
    return final.encode()


def same() -> None:
    runs = []
    for _ in range(2):
        daemon = h.start_daemon(MACHINE, PARAMS, f"{HERE}/config_test.yaml")
        listener = h.Listener()
        bus = Bus()
        bus.commands(50)
        bus.command_at(bus.utime)    # a duplicate utime, then a wrong machine
        bus.lc.publish("CHAINCOMP_COMMAND", h.command(7, bus.path[0], machine="vmc_xyz", utime=1))
        bus.update(1)                # no thermal model; an update refused or applied alike both times
        bus.reset()
        time.sleep(0.1)
        daemon.terminate()
        daemon.wait(5)
        final = h.final_status(listener, daemon)
        listener.close()
        runs.append(masked_status(final))
    print(f"same: two starts, status of {len(runs[0])} bytes, equal: {runs[0] == runs[1]}")
    assert runs[0] == runs[1]


def memcheck() -> None:
    config, thermal = streams_config(tempfile.mkdtemp())
    log = os.path.join(os.path.dirname(config), "memcheck.log")
    wrapper = ("valgrind", "--tool=memcheck", "--error-exitcode=99", "--track-origins=yes", f"--log-file={log}")
    t0 = time.perf_counter()
    daemon = h.start_daemon(MACHINE, PARAMS, config, extra=("--thermal", thermal), wrapper=wrapper)
    listener = h.Listener()
    bus = Bus()
    bus.commands(100)
    bus.update(2**63 - 1)
    bus.command_at(-2**63)
    for k in range(1, 7):
        bus.update(k)
        bus.readings(k * 1_000_000)
    bus.readings(INT64_MAX)
    bus.lc.publish("CHAINCOMP_PARAMS", b"\x00" * 9)
    bus.lc.publish("CHAINCOMP_CONTROL", h.control(False) + b"\x00")
    bus.reset()
    bus.commands(50)
    listener.wait_for(lambda: len(listener.targets) >= 151, 60)   # valgrind runs it some 30x slower
    time.sleep(0.2)
    daemon.terminate()
    code = daemon.wait(60)
    final = h.final_status(listener, daemon)
    listener.close()
    report = open(log).read()
    summary = [line for line in report.splitlines() if "ERROR SUMMARY" in line]
    print(f"memcheck: exit {code}, published {final.published} of {final.received}, "
          f"{summary[-1].split('== ')[-1] if summary else 'no summary'} ({time.perf_counter() - t0:.0f} s)")
    assert code == 0, report[-4000:]
    assert final.published == 151 and final.control_refused == 1


def main() -> int:
    h.require_namespace()
    t0 = time.perf_counter()
    chosen = sys.argv[1:] or ["lockout", "streams", "same", "twins", "tiny", "capped"]
    for scenario in (globals()[name] for name in chosen):
        scenario()
        print(f"{scenario.__name__}: {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
