"""chaincomp-lcm-bridge: a userspace LinuxCNC HAL component between the joints and chaincompd.

Each loop (about 1 kHz, paced by select on LCM's socket) it sends the joint commands as an
lcmt_axis_command (LinuxCNC joint units, mm and deg, converted to the machine file's axis
units), takes the daemon's targets back, and writes correction = target - command per joint
(converted back). When targets stop it holds the last correction, raises `stale` once the
newest applied target is older than --stale-ms and then ramps the correction out (or holds it:
--on-stale hold) by at most --max-step per loop and axis, never a larger step; `fault` rises
with `stale` (wire it to stop motion if the machine must not run uncompensated). It never
writes a non-finite value. With --params it starts chaincompd itself (as a child that dies with
it); run it through runtime/hal/chaincomp-lcm-bridge, which puts both in a network namespace of
their own so LCM's multicast never leaves it.

Pins (N = joint in the machine's axis order):
  chaincomp-bridge.joint.N.pos-cmd     float in   commanded joint position (joint.N.motor-pos-cmd)
  chaincomp-bridge.joint.N.correction  float out  correction to add (offset.N.offset)
  chaincomp-bridge.enable              bit in     compensate (the daemon ramps the correction in and out)
  chaincomp-bridge.age-ms              float out  age of the command whose target is applied, ms
  chaincomp-bridge.stale               bit out    no target newer than --stale-ms
  chaincomp-bridge.fault               bit out    stale, or the daemon exited
  chaincomp-bridge.clamped             bit out    the daemon limited the applied correction
  chaincomp-bridge.status              s32 out    the applied target's status (0 ok, 1 residual), -1 none
"""

from __future__ import annotations

import argparse
import collections
import ctypes
import math
import os
import select
import signal
import subprocess
import sys
import time

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
sys.path.insert(0, os.path.join(ROOT, "codegen"))
if "/usr/lib/python3/dist-packages" not in sys.path:
    sys.path.append("/usr/lib/python3/dist-packages")  # LinuxCNC's hal module (Debian's python3)

import hal  # noqa: E402
import lcm  # noqa: E402

from chaincomp.emit.buildtree import binary, import_lcmtypes  # noqa: E402
from chaincomp.errors import ChaincompError  # noqa: E402
from chaincomp.model.machine import load_machine  # noqa: E402

NAME = "chaincomp-bridge"


def parse_args(argv):
    p = argparse.ArgumentParser(prog="chaincomp-lcm-bridge", description=__doc__.split("\n\n")[0])
    p.add_argument("machine", metavar="MACHINE.yaml", help="the machine file whose axes are the joints")
    p.add_argument("--params", metavar="P.yaml", help="start chaincompd with these error values (else use a "
                                                       "running daemon on --url)")
    p.add_argument("--config", metavar="R.yaml", help="chaincompd's runtime settings (with --params)")
    p.add_argument("--url", default="udpm://239.255.76.67:7667?ttl=0", help="LCM URL (default: chaincompd's)")
    p.add_argument("--stale-ms", type=float, default=50.0, help="age after which targets are stale (default 50)")
    p.add_argument("--on-stale", choices=("ramp", "hold"), default="ramp",
                   help="when stale: ramp the correction out (default) or hold it")
    p.add_argument("--max-step", type=float, default=0.001,
                   help="largest change of a correction per loop when ramping out, mm or deg (default 0.001: "
                        "chaincompd's max_correction_step)")
    p.add_argument("--pid-file", help="write chaincompd's process id here")
    p.add_argument("--daemon-log", default="chaincompd.log",
                   help="chaincompd's output (default chaincompd.log in the current folder)")
    args = p.parse_args(argv)
    for name in ("stale_ms", "max_step"):
        v = getattr(args, name)
        if not math.isfinite(v) or v <= 0:
            p.error(f"--{name.replace('_', '-')}: expected a positive number, got {v}")
    return args


def start_daemon(args):
    """chaincompd as a child that gets SIGTERM when this process dies, its output in
    --daemon-log; waits for its ready line."""
    libc = ctypes.CDLL(None, use_errno=True)

    def die_with_parent():
        libc.prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG

    cmd = [binary("chaincompd"), "--machine", args.machine, "--params", args.params]
    if args.config:
        cmd += ["--config", args.config]
    try:
        log = open(args.daemon_log, "w+")
    except OSError as exc:
        raise ChaincompError(f"--daemon-log {args.daemon_log}: cannot write ({exc.strerror})") from None
    proc = subprocess.Popen(cmd, stdout=log, stderr=log, preexec_fn=die_with_parent)
    end = time.monotonic() + 120.0  # a machine outside configs/ is built first (about 25 s)
    while "; ready\n" not in open(args.daemon_log).read():
        if proc.poll() is not None or time.monotonic() > end:
            proc.kill()
            lines = open(args.daemon_log).read().strip().splitlines() or ["no output"]
            raise ChaincompError(f"chaincompd did not start (its log: {args.daemon_log}): {lines[-1]}")
        time.sleep(0.02)
    if args.pid_file:
        with open(args.pid_file, "w") as f:
            f.write(f"{proc.pid}\n")
    return proc


def main(argv=None) -> int:
    args = parse_args(argv)
    machine = load_machine(args.machine)
    types = import_lcmtypes()
    n = len(machine.axes)
    # LinuxCNC units (mm, deg) -> the axis's declared unit
    to_axis = [(math.pi / 180.0 if a.unit.kind == "angle" else 1.0) / a.unit.to_internal for a in machine.axes]

    daemon = start_daemon(args) if args.params else None
    lc = lcm.LCM(args.url)
    comp = hal.component(NAME)
    for i in range(n):
        comp.newpin(f"joint.{i}.pos-cmd", hal.HAL_FLOAT, hal.HAL_IN)
        comp.newpin(f"joint.{i}.correction", hal.HAL_FLOAT, hal.HAL_OUT)
    comp.newpin("enable", hal.HAL_BIT, hal.HAL_IN)
    comp.newpin("age-ms", hal.HAL_FLOAT, hal.HAL_OUT)
    comp.newpin("stale", hal.HAL_BIT, hal.HAL_OUT)
    comp.newpin("fault", hal.HAL_BIT, hal.HAL_OUT)
    comp.newpin("clamped", hal.HAL_BIT, hal.HAL_OUT)
    comp.newpin("status", hal.HAL_S32, hal.HAL_OUT)
    comp["status"] = -1

    latest = {}  # the newest target of this stream

    def on_target(_channel, data):
        try:
            t = types.lcmt_corrected_target.decode(data)
        except ValueError:
            return
        if t.machine != machine.name or t.num_axes != n or t.seq not in sent:
            return
        corr = [t.correction[i] / to_axis[i] for i in range(n)]
        if all(math.isfinite(c) for c in corr) and (not latest or t.seq > latest["seq"]):
            latest.update(seq=t.seq, utime=t.utime, correction=corr, flags=t.flags, status=t.status)

    lc.subscribe("CHAINCOMP_CORRECTED", on_target)
    sent = collections.OrderedDict()  # seq -> utime of the commands still awaited
    running = [True]
    signal.signal(signal.SIGTERM, lambda *_: running.__setitem__(0, False))
    signal.signal(signal.SIGINT, lambda *_: running.__setitem__(0, False))
    comp.ready()

    seq, enabled, last_control = 0, None, 0.0
    applied = [0.0] * n
    applied_seq = -1
    fd = lc.fileno()
    try:
        while running[0]:
            now = time.time()
            if comp["enable"] != enabled or now - last_control > 0.5:  # every message sets it
                enabled, last_control = comp["enable"], now
                ctl = types.lcmt_chaincomp_control()
                ctl.utime, ctl.enable, ctl.reset = int(now * 1e6), bool(enabled), False
                lc.publish("CHAINCOMP_CONTROL", ctl.encode())
            cmd = types.lcmt_axis_command()
            seq += 1
            cmd.utime, cmd.seq, cmd.machine, cmd.num_axes = int(now * 1e6), seq, machine.name, n
            cmd.axes = [comp[f"joint.{i}.pos-cmd"] * to_axis[i] for i in range(n)] + [0.0] * (8 - n)
            if all(math.isfinite(v) for v in cmd.axes):
                sent[seq] = cmd.utime
                while len(sent) > 2000:
                    sent.popitem(last=False)
                lc.publish("CHAINCOMP_COMMAND", cmd.encode())
            # targets that came back, waiting at most 1 ms
            deadline = now + 0.001
            while True:
                ready, _, _ = select.select([fd], [], [], max(0.0, deadline - time.time()))
                if not ready:
                    break
                lc.handle()
            if latest and latest["seq"] != applied_seq:
                applied_seq = latest["seq"]
                applied = list(latest["correction"])
                comp["clamped"] = bool(latest["flags"] & 4)
                comp["status"] = latest["status"]
            age_ms = (time.time() * 1e6 - latest["utime"]) / 1e3 if latest else float("inf")
            stale = age_ms > args.stale_ms
            if stale and args.on_stale == "ramp":  # towards zero, never a step beyond max_step
                applied = [c - max(-args.max_step, min(args.max_step, c)) for c in applied]
            comp["age-ms"] = age_ms if math.isfinite(age_ms) else 1e9
            comp["stale"] = stale
            comp["fault"] = stale or (daemon is not None and daemon.poll() is not None)
            if stale:
                comp["status"] = -1
            for i in range(n):
                comp[f"joint.{i}.correction"] = applied[i]
    finally:
        if daemon is not None and daemon.poll() is None:
            daemon.terminate()
            daemon.wait()
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except ChaincompError as exc:
        print(f"chaincomp-lcm-bridge: error: {exc}", file=sys.stderr)
        sys.exit(2)
