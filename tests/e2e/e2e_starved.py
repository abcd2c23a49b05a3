"""Every command accounted for under starvation (issue 39 item 3): chaincompd pinned to one
core beside a busy loop (and, given NICE, its main thread behind the loop while its receive
thread and LCM's are not: the daemon's command queue overflows), N commands at RATE Hz with a
burst of 100 control messages in the middle ending in enable=false. The status must account for
each command the test sent, exactly: received (answered or rejected by reason), dropped at the
daemon's full queue (counted one by one: queue_dropped), or lost in the kernel (the rest of those
missing by seq, within the kernel's own drop counter); LCM's own queues never full.

With RECV_BUF (bytes, the config's recv_buf_size) small, the kernel drops datagrams too: the
split must then hold with both queues losing.

    netns.sh python e2e_starved.py N RATE [NICE [RECV_BUF]]
"""

import os
import subprocess
import sys
import tempfile
import time

import lcm_harness as h
from common import HERE, MACHINE, PARAMS, toolpath

CORE = 0
BURST = 100


def main(n: int, rate: float, niceness: int, recv_buf: int) -> int:
    h.require_namespace()
    config = f"{HERE}/config_test.yaml"
    if recv_buf:
        with open(config) as f:
            text = f.read()
        config = os.path.join(tempfile.mkdtemp(), "small_buffer.yaml")
        with open(config, "w") as f:
            f.write(text + f"recv_buf_size: {recv_buf}\n")
    if len(os.sched_getaffinity(0)) > 1:
        os.sched_setaffinity(0, os.sched_getaffinity(0) - {CORE})  # the test beside, not on, the core
    hog = subprocess.Popen(["taskset", "-c", str(CORE), "sh", "-c", "while :; do :; done"])
    daemon = h.start_daemon(MACHINE, PARAMS, config, wrapper=("taskset", "-c", str(CORE)))
    # niceness is a thread's on Linux: the main thread's (its id is the process's), not that of
    # the daemon's receive thread or LCM's, both started before 'ready'
    try:
        os.setpriority(os.PRIO_PROCESS, daemon.pid, niceness)
        return starve(daemon, hog, n, rate, niceness)
    finally:
        hog.kill()
        if daemon.poll() is None:
            daemon.kill()


def starve(daemon, hog, n: int, rate: float, niceness: int) -> int:
    listener = h.Listener()
    pub = h.lcm.LCM(h.URL)
    path = toolpath(n + 1)
    try:
        pub.publish("CHAINCOMP_CONTROL", h.control(True))
        t0 = time.perf_counter()
        for i in range(n):
            h.pace(t0, i, rate)
            pub.publish("CHAINCOMP_COMMAND", h.command(i + 1, path[i]))
            if i == n // 2:  # the burst: enable, enable, ..., disable
                for k in range(BURST):
                    pub.publish("CHAINCOMP_CONTROL", h.control(k < BURST - 1))
        elapsed = time.perf_counter() - t0
    finally:
        hog.kill()
        hog.wait()
    # Commands after the stream, until one gets through (a full queue drops them too): commands
    # lost at its end (a burst's tail) are a gap before it.
    def through(count):
        return any(s.instance_id == daemon.instance and s.received + s.seq_missing >= count for s in listener.status)
    sent = n
    end = time.monotonic() + 90
    while not through(n + 1) and time.monotonic() < end:
        sent += 1
        pub.publish("CHAINCOMP_COMMAND", h.command(sent, path[n]))
        listener.wait_for(lambda: through(n + 1), 0.2)
    listener.wait_for(lambda: through(sent), 5)
    daemon.terminate()
    daemon.wait(10)
    s = h.final_status(listener, daemon)
    listener.close()
    lost = s.seq_missing
    kernel_lost = lost - s.queue_dropped
    print(f"starved (core {CORE}, busy loop beside, main thread nice {niceness}): sent {n} commands at {rate:g} Hz in "
          f"{elapsed:.2f} s, then {sent - n}; received {s.received} = published {s.published} + unpublished "
          f"{s.unpublished} + rejected {sum(s.rejected)} {list(s.rejected)}")
    print(f"sent {sent} = received {s.received} + queue dropped {s.queue_dropped} (queue of {s.queue_capacity}) + "
          f"kernel-lost {kernel_lost} (missing by seq {lost} in {s.seq_gaps} gaps; kernel drops, all channels: "
          f"{s.kernel_drops}); LCM's queues of {s.lcm_queue_capacity} found full {s.lcm_queue_full} times, "
          f"oversized {s.oversized}")
    control_kernel_lost = BURST + 1 - s.control_received - s.control_queue_dropped
    print(f"control: sent {BURST + 1}, received {s.control_received}, queue dropped {s.control_queue_dropped} (queue of "
          f"{s.control_queue_capacity}), kernel-lost {control_kernel_lost}; compensating at the end {s.compensating}")
    print(f"latency ns: compute p50 {s.latency_p50_ns} p99 {s.latency_p99_ns}; receipt-to-publish "
          f"p50 {s.receipt_p50_ns} p99 {s.receipt_p99_ns} max {s.receipt_max_ns}")
    # the daemon's own sum: every command it received was answered or rejected
    assert s.received == s.published + s.unpublished + sum(s.rejected)
    # every command sent: received, or missing by seq (the last one reveals a lost tail)
    assert s.received + lost == sent, (s.received, lost, sent)
    # exactness held: LCM discarded nothing uncounted (its queues never full), nothing oversized
    assert s.lcm_queue_full == 0 and s.oversized == 0
    # the split, exact: the drops at the daemon's queue are counted one by one, and the rest
    # is within what the kernel itself counts dropped at the daemon's sockets (every channel's)
    assert sent == s.received + s.queue_dropped + kernel_lost
    assert 0 <= s.queue_dropped <= lost, (s.queue_dropped, lost)
    assert 0 <= kernel_lost <= max(s.kernel_drops, 0), (kernel_lost, s.kernel_drops)
    # control messages the same way (they carry no seq: the test's count is the truth)
    assert 0 <= control_kernel_lost and control_kernel_lost + kernel_lost <= max(s.kernel_drops, 0)
    # the burst's final enable=false: applied, or its loss counted
    assert not s.compensating or control_kernel_lost + s.control_queue_dropped > 0
    return 0


if __name__ == "__main__":
    sys.exit(main(int(sys.argv[1]), float(sys.argv[2]), *(int(a) for a in (sys.argv[3:] + ["0", "0"])[:2])))
