"""chaincompd on a machine file outside configs/ (a model built at run time, or the library
given with --model): N commands along a smooth path within the machine's limits, every target
checked against the Python exact model to 1 nm, no heap allocation after warm-up.

Usage (inside netns.sh): e2e_built.py MACHINE.yaml PARAMS.yaml N [LIB.so]
"""

import math
import sys
import time

import numpy as np

import lcm_harness as h
from chaincomp import load_machine
from common import HERE, exact_check


def path_within_limits(machine, n: int) -> np.ndarray:
    """Each axis on a sine about 65 % of its range (away from the middle, where a rotary
    axis at 0 may be singular), 10 % amplitude, its own frequency; declared units."""
    t = np.linspace(0, 2 * math.pi, n, endpoint=False)
    cols = []
    for i, a in enumerate(machine.axes):
        lo, hi = a.limits
        cols.append(lo + (hi - lo) * (0.65 + 0.1 * np.sin((i % 3 + 1) * t + i)))
    return np.stack(cols, axis=1)


def main(machine_path: str, params: str, n: int, model: str | None) -> int:
    h.require_namespace()
    m = load_machine(machine_path)
    daemon = h.start_daemon(machine_path, params, f"{HERE}/config_test.yaml", preload=True, model=model)
    listener = h.Listener()
    pub = h.lcm.LCM(h.URL)
    paced, backlog = 200, 1000
    warm = paced + backlog
    path = path_within_limits(m, n + warm)
    t0 = time.perf_counter()
    for i in range(paced):
        h.pace(t0, i, 2000)
        pub.publish("CHAINCOMP_COMMAND", h.command(i + 1, path[i], machine=m.name))
    h.warm_backlog(daemon, lambda i: pub.publish("CHAINCOMP_COMMAND", h.command(i + 1, path[i], machine=m.name)),
                   paced, backlog)
    listener.wait_for(lambda: len(listener.targets) >= warm and any(s.published >= warm for s in listener.status), 10)
    allocations_after_warmup = listener.status[-1].allocations
    listener.targets.clear()
    t0 = time.perf_counter()
    for i in range(warm, warm + n):
        h.pace(t0, i - warm, 2000)
        pub.publish("CHAINCOMP_COMMAND", h.command(i + 1, path[i], machine=m.name))
    ok = listener.wait_for(lambda: len(listener.targets) >= n, 10)
    daemon.terminate()
    daemon.wait(5)
    listener.wait_for(lambda: any(s.final for s in listener.status), 3)
    listener.close()
    final = [s for s in listener.status if s.final][-1]
    seqs = [t.seq for _, t in listener.targets]
    corrected = np.array([t.axes[:len(m.axes)] for _, t in listener.targets])
    print(f"{m.name}: sent {n} after {warm} warm-up, test received {len(seqs)}, rejected {list(final.rejected)}")
    assert ok and seqs == list(range(warm + 1, warm + n + 1)), f"lost or reordered targets ({len(seqs)} of {n})"
    assert final.received == n + warm and final.published == n + warm and sum(final.rejected) == 0
    dp, dd = exact_check(path[np.array(seqs) - 1], corrected, machine_path, params)
    correction = float(np.max(np.abs(corrected - path[np.array(seqs) - 1])))
    print(f"exact model: max point error {dp:.2e} mm, max direction error {dd:.2e} rad; largest correction "
          f"{correction:.2e}; heap allocations after warm-up {final.allocations - allocations_after_warmup}")
    assert correction > 1e-4, "no correction at all: the errors did not reach the model"
    assert dp < 1e-6 and dd < 1e-9
    assert allocations_after_warmup >= 0, "the allocation counter is not loaded"
    assert final.allocations == allocations_after_warmup, "heap allocations in the steady state"
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4] if len(sys.argv) > 4 else None))
