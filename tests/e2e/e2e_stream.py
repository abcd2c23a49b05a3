"""Stream N commands at RATE Hz through chaincompd; every target checked against the exact
model; round-trip latency printed; allocations after start-up must be zero."""

import sys
import time

import numpy as np

import lcm_harness as h
from common import HERE, MACHINE, PARAMS, exact_check, toolpath


def main(rate: float, n: int) -> int:
    h.require_namespace()
    daemon = h.start_daemon(MACHINE, PARAMS, f"{HERE}/config_test.yaml", preload=True)
    listener = h.Listener()
    pub = h.lcm.LCM(h.URL)
    paced, backlog = 500, 1000
    warm = paced + backlog
    path = toolpath(n + warm)
    # Warm-up at the test's rate, then a deep backlog: LCM grows its receive-buffer pool
    # and ring to their working size.
    tw = time.perf_counter()
    for i in range(paced):
        h.pace(tw, i, rate)
        pub.publish("CHAINCOMP_COMMAND", h.command(i + 1, path[i]))
    h.warm_backlog(daemon, lambda i: pub.publish("CHAINCOMP_COMMAND", h.command(i + 1, path[i])), paced, backlog)
    listener.wait_for(lambda: len(listener.targets) >= warm and
                      any(s.published >= warm for s in listener.status), 10)
    allocations_after_warmup = listener.status[-1].allocations
    listener.targets.clear()
    sent = {}
    t0 = time.perf_counter()
    for i in range(warm, warm + n):
        if rate > 0:
            h.pace(t0, i - warm, rate)
        sent[i + 1] = time.perf_counter()
        pub.publish("CHAINCOMP_COMMAND", h.command(i + 1, path[i]))
    elapsed = time.perf_counter() - t0
    ok = listener.wait_for(lambda: len(listener.targets) >= n, 10)
    # the daemon hears its own last targets back a moment after the test does: let a periodic
    # status show them all before stopping it (else the final count races the echo)
    listener.wait_for(lambda: any(st.instance_id == daemon.instance and st.own_targets_heard >= n + warm
                                  for st in listener.status), 5)
    daemon.terminate()
    daemon.wait(5)
    final = h.final_status(listener, daemon)
    listener.close()
    targets = listener.targets
    h.print_losses(final)
    seqs = [t.seq for _, t in targets]
    rtt = np.array([(stamp - sent[t.seq]) * 1e6 for stamp, t in targets])
    corrected = np.array([t.axes[:5] for _, t in targets])
    print(f"rate {rate:g} Hz: sent {n} in {elapsed:.2f} s (after {warm} warm-up commands), daemon received "
          f"{final.received - warm}, published {final.published - warm}, test received {len(targets)}")
    print(f"round trip us: p50 {np.percentile(rtt, 50):.1f} p99 {np.percentile(rtt, 99):.1f} "
          f"p99.9 {np.percentile(rtt, 99.9):.1f} max {rtt.max():.1f}")
    print(f"daemon compute ns: p50 {final.latency_p50_ns} p99 {final.latency_p99_ns} "
          f"p99.9 {final.latency_p999_ns} max {final.latency_max_ns}; heap allocations after warm-up "
          f"{final.allocations - allocations_after_warmup} (during warm-up {allocations_after_warmup})")
    print(f"rejected by reason: {list(final.rejected)}")
    assert ok and len(targets) == n, f"lost {n - len(targets)} of {n}"
    assert seqs == list(range(warm + 1, warm + n + 1)), "targets out of order or duplicated"
    assert np.all(np.isfinite(corrected))
    assert final.received == n + warm and final.published == n + warm and sum(final.rejected) == 0
    # nothing lost anywhere the daemon can see: no gap, no kernel drop, its targets all on the bus
    assert final.seq_gaps == 0 and final.kernel_drops == 0 and final.own_targets_heard == n + warm
    assert final.foreign_targets == 0 and all(t.instance_id == daemon.instance for _, t in targets)
    dp, dd = exact_check(path[np.array(seqs) - 1], corrected)
    print(f"exact model: max point error {dp:.2e} mm, max direction error {dd:.2e} rad")
    assert dp < 1e-6 and dd < 1e-9
    assert allocations_after_warmup >= 0, "the allocation counter is not loaded"
    assert final.allocations == allocations_after_warmup, "heap allocations in the steady state"
    return 0


if __name__ == "__main__":
    sys.exit(main(float(sys.argv[1]), int(sys.argv[2])))
