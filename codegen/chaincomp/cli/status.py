"""``chaincomp status``: every chaincompd on the bus, from its status messages and targets."""

from __future__ import annotations

import contextlib
import json
import math
import os
import struct
import sys
import time

from ..emit.buildtree import _ROOT, import_lcmtypes
from ..errors import ChaincompError, NoAnswer
from ..escape import terminal
from ..model.units import UNITS
from .common import add_deprecated, add_format_argument, number, to_json

# configs/runtime/default.yaml's lcm_url and channels: where a daemon with default settings is
DEFAULT_URL = "udpm://239.255.76.67:7667?ttl=0"
STATUS_CHANNEL = "CHAINCOMP_STATUS"
TARGET_CHANNEL = "CHAINCOMP_CORRECTED"
DEFAULT_TIMEOUT = 1.5      # the default status period (1 s) and a margin
# lcmt_chaincomp_status.rejected[i], in the order the .lcm file lists them
REASONS = ("undecodable", "wrong machine", "wrong axis count", "non-finite", "out of limits",
           "step too large", "duplicate seq", "out-of-order seq", "compensation failed")
# lcmt_chaincomp_status.params_refused[i], likewise (runtime/include/chaincomp/params_update.hpp)
PARAMS_REASONS = ("undecodable", "wrong machine", "another instance", "bad count", "unknown name", "not an error",
                  "repeated name", "non-finite", "out of bound", "stale seq", "too frequent")
# lcmt_chaincomp_status.readings_refused[i] (runtime/include/chaincomp/thermal.hpp)
READING_REASONS = ("undecodable", "wrong machine", "bad value", "time not increasing")
COUNTERS = ("received", "published", "unpublished", "clamped", "held_back", "clamped_input", "seq_gaps",
            "seq_missing", "queue_dropped", "stream_restarts", "resets", "kernel_drops", "own_targets_heard",
            "foreign_targets")
FLAGS = ((1, "compensating"), (2, "ramping"), (4, "clamped"), (8, "residual"), (16, "clamped input"))


def add_parser(sub) -> None:
    p = sub.add_parser("status", help="live view of every chaincompd on the bus",
                       description="Listen to the daemons' status and corrected-target channels and show, per "
                                   "daemon (told apart by its instance id): machine, compensation on, off or "
                                   "ramping, counters (rejections by reason), latency percentiles, the "
                                   "current correction per axis (µm, arcsec) and the age of the last command. "
                                   "The view redraws in place until Ctrl-C. With --once: listen for --timeout "
                                   "seconds, print and exit 0, or exit 4 (no answer) when no daemon was heard.")
    p.add_argument("machines", nargs="*", metavar="MACHINE.yaml",
                   help="machine descriptions naming the daemons' axes and units (default: "
                        "configs/machines/NAME.yaml of this checkout for a daemon's machine NAME)")
    p.add_argument("--url", default=DEFAULT_URL,
                   help=f"LCM URL the daemons use (default {DEFAULT_URL}, configs/runtime/default.yaml's)")
    p.add_argument("--once", action="store_true", help="print one view and exit (4: no daemon heard)")
    add_format_argument(p, what="output format (live json: one JSON document per line and refresh)")
    p.add_argument("--timeout", type=number(0, 3600, above=True), default=DEFAULT_TIMEOUT,
                   help=f"with --once: seconds to listen, at least one daemon's status period (default "
                        f"{DEFAULT_TIMEOUT} s, for the default period of 1 s)")
    p.add_argument("--refresh", type=number(0.05, 3600), default=0.5,
                   help="seconds between redraws of the live view (default 0.5)")
    add_deprecated(p, "--machine", "the arguments (MACHINE.yaml ...)", "machine_option", append=True, default=[],
                   metavar="MACHINE.yaml")
    p.set_defaults(run=run)


class Bus:
    """The last status and the last target of every daemon instance heard."""

    def __init__(self, url: str):
        self.types = import_lcmtypes()
        import lcm
        # liblcm prints its own line on stderr for a bad URL: ours is the one the user sees
        if not url.strip():   # liblcm would open its default (LCM_DEFAULT_URL, else multicast) unasked
            raise ChaincompError(f"--url: empty (the default is {DEFAULT_URL})")
        with _quiet_stderr():
            try:
                self.lc = lcm.LCM(url)
            except RuntimeError:
                raise ChaincompError(f"--url: cannot open LCM at {url!r}") from None
        self.status: dict[int, tuple[float, object]] = {}    # instance -> (monotonic time heard, status)
        self.targets: dict[int, object] = {}
        self.period: dict[int, float] = {}     # instance -> seconds between its last two statuses
        self.lc.subscribe(STATUS_CHANNEL, self._on_status).set_queue_capacity(1000)
        self.lc.subscribe(TARGET_CHANNEL, self._on_target).set_queue_capacity(1000)

    def _on_status(self, channel, data):
        try:
            s = self.types.lcmt_chaincomp_status.decode(data)
        except (ValueError, struct.error):  # not our type (another program on the channel): nothing to show
            return
        last = self.status.get(s.instance_id)
        if last and s.utime > last[1].utime:   # the daemon's period, to tell when it falls silent
            self.period[s.instance_id] = (s.utime - last[1].utime) / 1e6
        self.status[s.instance_id] = (time.monotonic(), s)

    def _on_target(self, channel, data):
        try:
            t = self.types.lcmt_corrected_target.decode(data)
        except (ValueError, struct.error):
            return
        self.targets[t.instance_id] = t

    def listen(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            self.lc.handle_timeout(max(1, int(left * 1000)))


@contextlib.contextmanager
def _quiet_stderr():
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


class Axes:
    """Names and wire units of a machine's axes, by machine name: from --machine files, else
    this checkout's configs/machines/NAME.yaml; unknown machines get numbered axes."""

    def __init__(self, paths: list[str]):
        from ..model.machine import load_machine
        self._load = load_machine
        self.known = {}
        for path in paths:
            m = load_machine(path)
            self.known[m.name] = [(a.name, a.unit) for a in m.axes]

    def of(self, name: str):
        if name not in self.known:
            path = os.path.join(_ROOT, "configs", "machines", f"{name}.yaml")
            axes = None
            # the name comes off the bus: a plain file name only
            if name and "\0" not in name and os.path.basename(name) == name and os.path.isfile(path):
                with contextlib.suppress(ChaincompError):
                    m = self._load(path)
                    axes = [(a.name, a.unit) for a in m.axes] if m.name == name else None
            self.known[name] = axes
        return self.known[name]


def correction(values, axes) -> list[dict]:
    """Per axis the correction on the wire (the axis's unit) in µm or arcsec; unknown axes
    keep the wire value (mm or deg, which one the machine file would tell)."""
    out = []
    for i, v in enumerate(values):
        if axes is None or i >= len(axes):
            out.append({"axis": f"#{i}", "value": v, "unit": "mm|deg"})
            continue
        name, unit = axes[i]
        internal = v * unit.to_internal          # mm or rad
        if unit.kind == "length":
            out.append({"axis": name, "value": internal / UNITS["um"].to_internal, "unit": "um"})
        else:
            out.append({"axis": name, "value": internal / UNITS["arcsec"].to_internal, "unit": "arcsec"})
    return out


SILENT_PERIODS = 3     # statuses missed before a daemon (killed, stopped, cut off) shows as silent


def describe(status, heard_at: float, period: float | None, target, axes, now: float, now_us: int) -> dict:
    """One daemon as a plain document (JSON's, and what the text view shows)."""
    s = status
    if s.final:
        state = "exited"
    elif period is not None and now - heard_at > SILENT_PERIODS * period + 0.5:
        state = "silent"
    elif 0.0 < s.ramp < 1.0:
        state = "ramping"
    else:
        state = "enabled" if s.compensating else "disabled"
    doc = {
        "instance": f"{s.instance_id & 0xFFFFFFFFFFFFFFFF:016x}",
        "machine": s.machine, "state": state, "compensating": bool(s.compensating), "ramp": s.ramp,
        "final": bool(s.final), "uptime_s": s.uptime_us / 1e6, "status_age_s": now - heard_at,
        "status_period_s": period,
        "counters": {name: getattr(s, name) for name in COUNTERS},
        "rejected": dict(zip(REASONS, s.rejected)),
        "params_updates": {"version": s.params_version, "last_seq": s.params_seq, "received": s.params_received,
                           "refused": dict(zip(PARAMS_REASONS, s.params_refused))},
        "readings": {"received": s.readings_received, "refused": dict(zip(READING_REASONS, s.readings_refused))},
        "control": {"received": s.control_received, "refused": s.control_refused},
        # what the targets published correct, and the objective (mm^2, summed) before and after
        "objective": {"direction_weight_mm": s.direction_weight, "full": s.targets_full,
                      "partial": s.targets_partial, "uncorrected": s.targets_uncorrected,
                      "worse": s.targets_worse, "before_sum_mm2": s.objective_before,
                      "after_sum_mm2": s.objective_after},
        "latency_ns": {"window": s.window, "p50": s.latency_p50_ns, "p99": s.latency_p99_ns,
                       "p999": s.latency_p999_ns, "max": s.latency_max_ns},
        # from LCM's receive stamp to the target published: the waiting in the queues too
        "receipt_latency_ns": {"p50": s.receipt_p50_ns, "p99": s.receipt_p99_ns, "max": s.receipt_max_ns},
        # the daemon's queues, one per stream: their capacity and the messages dropped there full;
        # LCM's own queues behind them, and how often one was found full (the drops then inexact)
        "queues": {"commands": {"capacity": s.queue_capacity, "dropped": s.queue_dropped},
                   "control": {"capacity": s.control_queue_capacity, "dropped": s.control_queue_dropped},
                   "params": {"dropped": s.params_queue_dropped}, "readings": {"dropped": s.readings_queue_dropped},
                   "targets": {"dropped": s.targets_queue_dropped}, "oversized": s.oversized,
                   "lcm": {"capacity": s.lcm_queue_capacity, "found_full": s.lcm_queue_full}},
        "recv_buf_bytes": s.recv_buf_bytes, "foreign_instance": f"{s.foreign_instance & 0xFFFFFFFFFFFFFFFF:016x}",
        "model_hash": s.model_hash, "params_file": s.params_file, "params_hash": s.params_hash,
        "config_file": s.config_file, "allocations": s.allocations,
        "realtime": {"mlockall": bool(s.mlockall_ok), "sched_fifo": bool(s.sched_fifo_ok),
                     "cpu_pinned": bool(s.cpu_pinned_ok)},
        "last_target": None,
    }
    if target is not None:
        n = max(0, min(target.num_axes, len(target.correction)))
        doc["last_target"] = {
            "seq": target.seq, "command_age_s": (now_us - target.utime) / 1e6,
            "flags": [name for bit, name in FLAGS if target.flags & bit],
            "correction": correction(list(target.correction[:n]), axes),
        }
    return doc


def snapshot(bus: Bus, axes: Axes, url: str) -> dict:
    now, now_us = time.monotonic(), int(time.time() * 1e6)
    daemons = [describe(s, at, bus.period.get(i), bus.targets.get(i), axes.of(s.machine), now, now_us)
               for i, (at, s) in sorted(bus.status.items(), key=lambda kv: (kv[1][1].machine, kv[0]))]
    return {"url": url, "daemons": daemons}


def _us(ns: int) -> str:
    if ns < 0:
        return "-"
    return f"{ns / 1e3:.1f} µs" if ns < 1_000_000 else f"{ns / 1e6:.2f} ms"


def _objective_line(o: dict, published: int) -> str:
    """Full / partial / uncorrected targets and the objective's RMS (as a length) before and after."""
    line = (f"  corrects  full {o['full']}  partial {o['partial']}  uncorrected {o['uncorrected']}  "
            f"worse than the command {o['worse']}")
    if published:
        before, after = (1e3 * math.sqrt(max(o[k], 0.0) / published) for k in ("before_sum_mm2", "after_sum_mm2"))
        line += f"  objective RMS {before:.3g} µm -> {after:.3g} µm (direction at {o['direction_weight_mm']:g} mm)"
    return line


def render_text(doc: dict) -> str:
    if not doc["daemons"]:
        return f"no chaincompd heard on {doc['url']}\n"
    lines = [f"{len(doc['daemons'])} chaincompd on {doc['url']}"]
    for d in doc["daemons"]:
        c, state, q = d["counters"], d["state"], d["queues"]
        if state == "ramping":
            state += f" {100 * d['ramp']:.0f}%"
        rejected = sum(d["rejected"].values())
        reasons = ", ".join(f"{k} {v}" for k, v in d["rejected"].items() if v)
        lat = d["latency_ns"]
        lines += [
            "",
            f"{terminal(d['machine'])}  instance {d['instance']}  {state}  up {d['uptime_s']:.1f} s  "
            f"status {d['status_age_s']:.1f} s ago",
            f"  commands  received {c['received']}  published {c['published']}  rejected {rejected}"
            + (f" ({reasons})" if reasons else "")
            + (f"  unpublished {c['unpublished']}" if c["unpublished"] else "")
            + f"  clamped {c['clamped']} (held back {c['held_back']})  clamped input {c['clamped_input']}",
            f"  stream    seq gaps {c['seq_gaps']} ({c['seq_missing']} missing)  restarts {c['stream_restarts']}  "
            f"resets {c['resets']}  kernel drops {c['kernel_drops']}  queue dropped {c['queue_dropped']} "
            f"({q['commands']['capacity']} deep)"
            + (f"  control messages {d['control']['received']} (refused {d['control']['refused']})"
               if d["control"]["received"] else ""),
            f"  queues    dropped: control {q['control']['dropped']}  params {q['params']['dropped']}  "
            f"readings {q['readings']['dropped']}  targets {q['targets']['dropped']}  oversized {q['oversized']}  "
            f"LCM's found full {q['lcm']['found_full']} times"
            + ("  (drops not exact)" if q["lcm"]["found_full"] else ""),
            f"  params    version {d['params_updates']['version']} (last seq {d['params_updates']['last_seq']})  "
            f"updates received {d['params_updates']['received']}  refused "
            f"{sum(d['params_updates']['refused'].values())}"
            + "".join(f", {k} {v}" for k, v in d["params_updates"]["refused"].items() if v)
            + (f"  temperature readings {d['readings']['received']}, refused "
               f"{sum(d['readings']['refused'].values())}" if d["readings"]["received"] else ""),
            f"  targets   own heard back {c['own_targets_heard']}  foreign {c['foreign_targets']}"
            + (f" (last from instance {d['foreign_instance']})" if c["foreign_targets"] else ""),
            _objective_line(d["objective"], c["published"]),
            f"  latency   p50 {_us(lat['p50'])}  p99 {_us(lat['p99'])}  p99.9 {_us(lat['p999'])}  "
            f"max {_us(lat['max'])}  (last {lat['window']} commands)  receipt to publish p50 "
            f"{_us(d['receipt_latency_ns']['p50'])}  p99 {_us(d['receipt_latency_ns']['p99'])}" if lat["window"] else
            "  latency   no command published yet",
        ]
        t = d["last_target"]
        if t is None:
            lines.append("  last command: none heard while listening")
            continue
        units = {"um": "µm", "arcsec": "arcsec", "mm|deg": "mm|deg"}
        lines.append("  correction " + "  ".join(f"{terminal(a['axis'])} {a['value']:+.3f} {units[a['unit']]}"
                                                for a in t["correction"]))
        flags = f" [{', '.join(t['flags'])}]" if t["flags"] else ""
        lines.append(f"  last command seq {t['seq']}, {t['command_age_s']:.2f} s ago{flags}")
    return "\n".join(lines) + "\n"


def _render(doc: dict, fmt: str, live: bool) -> str:
    if fmt == "text":
        return render_text(doc)
    text = to_json(doc)
    return (json.dumps(json.loads(text), separators=(",", ":")) if live else text) + "\n"


def run(args) -> int:
    axes = Axes(args.machines + args.machine_option)
    bus = Bus(args.url)
    if args.once:
        bus.listen(args.timeout)
        doc = snapshot(bus, axes, args.url)
        if not doc["daemons"]:
            raise NoAnswer(f"no chaincompd heard on {args.url} within {args.timeout:g} s")
        sys.stdout.write(_render(doc, args.format, live=False))
        return 0
    redraw = args.format == "text" and sys.stdout.isatty()
    if redraw:
        sys.stdout.write("\x1b[?25l\x1b[2J")   # a clear screen, no cursor flickering over the view
    try:
        while True:
            bus.listen(args.refresh)
            text = _render(snapshot(bus, axes, args.url), args.format, live=True)
            # home, the view, then clear what an older, longer view left below it
            sys.stdout.write("\x1b[H" + text.replace("\n", "\x1b[K\n") + "\x1b[J" if redraw else text)
            sys.stdout.flush()
    finally:
        if redraw:
            sys.stdout.write("\x1b[?25h\n")
            sys.stdout.flush()
