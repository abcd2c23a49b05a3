"""Params updates during a 1 kHz command stream through chaincompd: the good ones applied
(the targets then match the exact model with the new values), the hostile ones refused and
counted by reason (unknown name, NaN, a huge value, a constant, a repeated name, another
machine, another instance, a flood at about 10 kHz); no target moves by more than
max_correction_step, no command is lost, no heap allocation in the steady state, and
chaincomp_replay of the same events reproduces every target bit for bit."""

import os
import sys
import tempfile
import time

import numpy as np
import yaml

import lcm_harness as h
from common import MACHINE, PARAMS, exact_errors, toolpath
from chaincomp_lcm import lcmt_params_update

STEP = 0.002          # mm and deg: max_correction_step
N = 3000              # commands at 1 kHz
U1 = {"EXX": 0.024, "EYY": -0.015, "Ocx": 0.02}       # internal units (mm)
U2 = {"EXX": 0.014, "EYY": -0.005, "Ocx": 0.01}       # the flood's values
FLOOD = 2000
REASONS = ("undecodable", "wrong machine", "another instance", "bad count", "unknown name", "not an error",
           "repeated name", "non-finite", "out of bound", "stale seq", "too frequent")


def update(seq, values, machine="five_axis_ac", instance=0) -> bytes:
    m = lcmt_params_update()
    m.utime, m.seq, m.machine, m.instance_id = int(time.time() * 1e6), seq, machine, instance
    m.num_values = len(values)
    m.names = [k for k, _ in values]
    m.values = [float(v) for _, v in values]
    return m.encode()


def params_with(values: dict, path: str) -> str:
    doc = yaml.safe_load(open(PARAMS))
    doc["values"].update({k: f"{v!r} mm" for k, v in values.items()})
    with open(path, "w") as f:
        yaml.safe_dump(doc, f)
    return path


def main() -> int:
    h.require_namespace()
    tmp = tempfile.mkdtemp()
    config = os.path.join(tmp, "config.yaml")
    with open(config, "w") as f:
        f.write(f'lcm_url: "udpm://239.255.76.67:7667?ttl=0"\nstatus_period: 0.05\nlatency_window: 20000\n'
                f"ramp_time: 0.0\nlinear_axes: {{max_step: 5.0, max_correction: 1.0, max_correction_step: {STEP}}}\n"
                f"rotary_axes: {{max_step: 5.0, max_correction: 1.0, max_correction_step: {STEP}}}\n")
    daemon = h.start_daemon(MACHINE, PARAMS, config, preload=True)
    listener = h.Listener()
    log_path = os.path.join(tmp, "events.lcmlog")
    pub = h.LoggedPublisher(log_path)
    send = pub.publish

    hostile = [("unknown name", [("NoSuch", 0.0)]), ("non-finite", [("EXX", float("nan"))]),
               ("out of bound", [("EXX", 5.0)]), ("not an error", [("G", 151.0)]),
               ("repeated name", [("EXX", 0.0), ("EXX", 0.001)]), ("bad count", [])]
    paced, backlog = 500, 1000
    W = paced + backlog
    path = toolpath(W + N)

    def command(i):
        send("CHAINCOMP_COMMAND", h.command(i + 1, path[i], utime=1_000_000_000 + 1000 * i))

    # Warm-up as e2e_stream's (LCM grows its rings to a deep backlog), with a burst of 200
    # updates without values on the params channel (refused: bad count): LCM allocates for a
    # channel at its first message. The steady state starts after it.
    warm_refusals = 200
    tw = time.perf_counter()
    for i in range(paced):
        h.pace(tw, i, 1000.0)
        command(i)
        if i == 10:
            for _ in range(warm_refusals):
                send("CHAINCOMP_PARAMS", update(0, []))
    h.warm_backlog(daemon, command, paced, backlog)
    listener.wait_for(lambda: any(s.instance_id == daemon.instance and s.published >= W and
                                  s.params_received >= warm_refusals for s in listener.status), 10)
    allocations_after_warmup = [s for s in listener.status if s.instance_id == daemon.instance][-1].allocations

    t0 = time.perf_counter()
    seq = 1
    for i in range(W, W + N):
        h.pace(t0, i - W, 1000.0)
        command(i)
        k = i - W
        if k == 1000:
            send("CHAINCOMP_PARAMS", update(seq, U1.items()))
            seq += 1
        elif k == 1500:
            for _, values in hostile:
                send("CHAINCOMP_PARAMS", update(seq, values))
                seq += 1
            send("CHAINCOMP_PARAMS", update(seq, U1.items(), machine="vmc_xyz"))
            send("CHAINCOMP_PARAMS", update(seq + 1, U1.items(), instance=daemon.instance ^ 1))
            send("CHAINCOMP_PARAMS", b"\x00" * 7)
            seq += 2
        elif 1600 <= k < 1800:   # ten updates per command: 10 kHz
            for _ in range(FLOOD // 200):
                send("CHAINCOMP_PARAMS", update(seq, U2.items()))
                seq += 1
        elif k == 2500:
            send("CHAINCOMP_PARAMS", update(seq, U1.items()))
            seq += 1
    pub.close()
    # every numbered update, the junk, the warm-up's
    expected = seq - 1 + 1 + warm_refusals
    listener.wait_for(lambda: len([t for _, t in listener.targets if t.instance_id == daemon.instance]) >= W + N, 10)
    listener.wait_for(lambda: any(s.instance_id == daemon.instance and s.params_received >= expected
                                  for s in listener.status), 5)
    daemon.terminate()
    daemon.wait(5)
    final = h.final_status(listener, daemon)
    listener.close()
    h.print_losses(final)
    refused = dict(zip(REASONS, final.params_refused))
    print(f"params updates: received {final.params_received}, applied {final.params_version} (last seq "
          f"{final.params_seq}), refused {refused}")
    targets = {t.seq: t for _, t in listener.targets if t.instance_id == daemon.instance}
    total = W + N
    assert len(targets) == total and final.published == total and sum(final.rejected) == 0, \
        (len(targets), list(final.rejected))
    assert final.params_received == expected
    for reason, _ in hostile:
        assert refused[reason] == (1 + warm_refusals if reason == "bad count" else 1), (reason, refused)
    assert refused["wrong machine"] == refused["another instance"] == refused["undecodable"] == 1
    flood_applied = final.params_version - 2
    assert flood_applied >= 1 and refused["too frequent"] == FLOOD - flood_applied, refused
    assert refused["stale seq"] == 0 and final.params_seq == seq - 1
    print(f"flood of {FLOOD} at 10 kHz: {flood_applied} applied (one per 10 ms of command time), "
          f"{refused['too frequent']} refused as too frequent")

    corr = np.array([targets[s].correction[:5] for s in range(1, total + 1)])
    step = np.max(np.abs(np.diff(corr, axis=0)), axis=0)
    print(f"largest change of the correction per command: {step.tolist()} (limit {STEP})")
    assert np.all(step <= STEP * (1 + 1e-9))
    # settled after U1 (20 um at 2 um per command: 10 commands), before the hostile burst:
    # the exact model with U1's values at those targets
    axes = np.array([targets[s].axes[:5] for s in range(1, total + 1)])
    u1 = params_with(U1, os.path.join(tmp, "u1.yaml"))
    dp, _ = exact_errors(path[W + 1100:W + 1500], axes[W + 1100:W + 1500], params=u1)
    print(f"after the first update, settled: largest tool error by the exact model with its values {dp.max():.2e} mm")
    assert dp.max() < 1e-6
    dp, _ = exact_errors(path[W + 2600:], axes[W + 2600:], params=u1)
    assert dp.max() < 1e-6
    print(f"heap allocations after warm-up {final.allocations - allocations_after_warmup} (during warm-up "
          f"{allocations_after_warmup})")
    assert allocations_after_warmup >= 0, "the allocation counter is not loaded"
    assert final.allocations == allocations_after_warmup, "heap allocations in the steady state"

    offline = h.replay(MACHINE, PARAMS, config, log_path, os.path.join(tmp, "replay.lcmlog"))
    differing = [s for s in targets if s not in offline or h.target_key(targets[s]) != h.target_key(offline[s])]
    print(f"replay: {len(offline)} targets, differing from the daemon's: {len(differing)}")
    assert len(offline) == total and not differing, differing[:5]
    return 0


if __name__ == "__main__":
    sys.exit(main())
