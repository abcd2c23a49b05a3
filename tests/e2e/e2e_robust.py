"""Every kind of bad input, then 10^5 random payloads: each is rejected and counted by
reason, no bad target is published, and the daemon still answers good commands."""

import random
import sys
import time

import numpy as np

import lcm_harness as h
from common import HERE, MACHINE, PARAMS, toolpath
from chaincomp import load_machine

REASONS = ["undecodable", "wrong_machine", "wrong_axis_count", "non_finite", "out_of_limits",
           "step_too_large", "duplicate_seq", "out_of_order_seq", "compensation_failed"]


def main(random_count: int) -> int:
    h.require_namespace()
    m = load_machine(MACHINE)
    limits = np.array([a.limits for a in m.axes])
    daemon = h.start_daemon(MACHINE, PARAMS, f"{HERE}/config_test.yaml")
    listener = h.Listener()
    pub = h.lcm.LCM(h.URL)
    send = lambda payload: pub.publish("CHAINCOMP_COMMAND", payload)  # noqa: E731
    path = toolpath(1000)
    expected = dict.fromkeys(REASONS, 0)
    seq = 0

    def good():
        nonlocal seq
        seq += 1
        send(h.command(seq, path[seq % 1000]))

    good()
    bad = {
        "non_finite": [h.command(seq + 1, [float("nan"), 0, -200, 30, -45]),
                       h.command(seq + 1, [0, float("inf"), -200, 30, -45])],
        "wrong_axis_count": [h.command(seq + 1, [0, 0, -200, 30])],
        "wrong_machine": [h.command(seq + 1, path[1], machine="angle_head"),
                          h.command(seq + 1, path[1], machine="five_axis_ac\0garbage"),
                          h.command(seq + 1, path[1], machine="")],
        "out_of_limits": [h.command(seq + 1, [limits[0, 1] + 1, 0, -200, 30, -45])],
        "step_too_large": [h.command(seq + 1, path[1] + np.array([6.0, 0, 0, 0, 0]))],
        "duplicate_seq": [h.command(seq, path[1])],
        "out_of_order_seq": [h.command(seq - 1, path[1])],
        # (a valid command with one byte more: refused whole, as updates and readings are)
        "undecodable": [b"", b"\x00" * 3, b"not an lcm message at all", h.command(seq + 1, path[1]) + b"\x00"],
    }
    for reason, payloads in bad.items():
        for p in payloads:
            send(p)
            expected[reason] += 1
            time.sleep(0.001)
    # The first command back from the spike is itself a jump from the last valid command.
    send(h.command(seq + 1, path[(seq + 1) % 1000]))
    expected["step_too_large"] += 1
    time.sleep(0.001)
    good()

    # Random payloads: half pure noise, half with the right fingerprint and random fields.
    fingerprint = h.command(1, path[0])[:8]
    rng = random.Random(99)
    sent_random = 0
    for i in range(random_count):
        if i % 2:
            body = bytes(rng.getrandbits(8) for _ in range(rng.randrange(0, 120)))
            send(body)
        else:
            body = fingerprint + bytes(rng.getrandbits(8) for _ in range(rng.randrange(0, 120)))
            send(body)
        sent_random += 1
        if i % 20 == 19:
            # 10 kHz in groups of 20, well within the socket buffer and LCM's queue
            time.sleep(0.002)
    for _ in range(10):
        good()
        time.sleep(0.001)
    total_good = seq
    listener.wait_for(lambda: len(listener.targets) >= total_good, 10)
    daemon.terminate()
    daemon.wait(5)
    final = h.final_status(listener, daemon)
    listener.close()
    h.print_losses(final)
    rejected = dict(zip(REASONS, final.rejected))
    print(f"sent {total_good} good, {sum(expected.values())} bad, {sent_random} random; daemon received "
          f"{final.received}, published {final.published}")
    print("rejected by reason:", {k: v for k, v in rejected.items() if v})
    targets = np.array([t.axes[:5] for _, t in listener.targets])
    assert final.received == total_good + sum(expected.values()) + sent_random, "payloads lost"
    assert np.all(np.isfinite(targets)), "a non-finite target was published"
    assert np.all((targets >= limits[:, 0]) & (targets <= limits[:, 1])), "an out-of-limit target was published"
    # The good commands, and the random ones that happened to be acceptable, were published;
    # every other message is counted under exactly one reason.
    assert final.published + sum(final.rejected) == final.received
    # With this seed no random payload decodes into a command: every count is exact.
    expected["undecodable"] += sent_random
    assert rejected == expected, (rejected, expected)
    assert [t.seq for _, t in listener.targets][:2] == [1, 2]
    assert [t.seq for _, t in listener.targets][-10:] == list(range(total_good - 9, total_good + 1))
    assert rejected["compensation_failed"] == 0
    assert final.seq_gaps == 0 and final.stream_restarts == 0 and final.kernel_drops == 0
    return 0


if __name__ == "__main__":
    sys.exit(main(int(sys.argv[1]) if len(sys.argv) > 1 else 100000))
