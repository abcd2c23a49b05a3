"""chaincomp status: the view of hand-made messages (units converted by hand), the live loop
on a captured console (no TTY) and on a pretended terminal, the verb's refusals, and the
end-to-end run against real daemons in a network namespace (tests/e2e/e2e_status.py)."""

import argparse
import io
import json
import os
import re
import subprocess
import sys

import pytest
import yaml

from helpers import ROOT, machine_path, needs_netns, run_cli
from chaincomp.emit.buildtree import import_lcmtypes
from chaincomp.cli import status

T = import_lcmtypes()
LCM_DIR = os.path.join(ROOT, "runtime", "lcmtypes")


def _fields(lcm_file: str) -> list[str]:
    text = open(os.path.join(LCM_DIR, lcm_file)).read()
    return re.findall(r"^\s*(?:int64_t|int32_t|double|boolean|string)\s+(\w+)", text, re.M)


def test_defaults_are_the_daemons():
    cfg = yaml.safe_load(open(os.path.join(ROOT, "configs", "runtime", "default.yaml")))
    assert status.DEFAULT_URL == cfg["lcm_url"]
    assert (status.STATUS_CHANNEL, status.TARGET_CHANNEL) == (cfg["channels"]["status"], cfg["channels"]["corrected"])
    assert status.DEFAULT_TIMEOUT > cfg["status_period"]


def test_reasons_and_counters_are_the_status_types():
    text = open(os.path.join(LCM_DIR, "lcmt_chaincomp_status.lcm")).read()
    listed = re.search(r"// 0 undecodable.*?\n(.*?)\n\n", text, re.S).group(0)
    reasons = re.findall(r"(\d) ([a-z -]+?)(?:,|\n)", listed.replace("//", " "))
    assert [int(i) for i, _ in reasons] == list(range(9))
    assert tuple(r.strip() for _, r in reasons) == status.REASONS
    listed = re.search(r"// params_refused.*?\n(.*?)\n\n", text, re.S).group(1)
    reasons = re.findall(r"(\d+) ([a-z -]+?)(?: \(.*?\))?(?:,|\n|$)", listed.replace("//", " "))
    assert [int(i) for i, _ in reasons] == list(range(11))
    assert tuple(r.strip() for _, r in reasons) == status.PARAMS_REASONS
    listed = re.search(r"// readings_refused.*?\n(.*?)\n\n", text, re.S).group(1)
    reasons = re.findall(r"(\d+) ([a-z -]+?)(?:,|\n|$)", listed.replace("//", " "))
    assert tuple(r.strip() for _, r in reasons) == status.READING_REASONS
    fields = _fields("lcmt_chaincomp_status.lcm")
    assert set(status.COUNTERS) <= set(fields)
    consts = dict(re.findall(r"FLAG_(\w+) = (\d+)", open(os.path.join(LCM_DIR, "lcmt_corrected_target.lcm")).read()))
    assert {int(v): k.lower().replace("_", " ") for k, v in consts.items()} == dict(status.FLAGS)


def _status(**kw):
    s = T.lcmt_chaincomp_status()
    s.machine, s.instance_id, s.uptime_us, s.received, s.published = "five_axis_ac", 0x1234, 12_500_000, 100, 97
    s.rejected = [0, 0, 0, 0, 2, 1, 0, 0, 0]
    s.compensating, s.ramp, s.window = True, 1.0, 97
    s.latency_p50_ns, s.latency_p99_ns, s.latency_p999_ns, s.latency_max_ns = 12_300, 45_000, 2_500_000, 2_600_000
    s.kernel_drops, s.recv_buf_bytes = 0, 4194304
    for k, v in kw.items():
        setattr(s, k, v)
    return s


def _target(correction, machine="five_axis_ac", utime=1_000_000_000, flags=1):
    t = T.lcmt_corrected_target()
    t.machine, t.instance_id, t.seq, t.utime, t.flags = machine, 0x1234, 97, utime, flags
    t.num_axes = len(correction)
    t.correction = list(correction) + [0.0] * (8 - len(correction))
    return t


def _doc(s, t, axes=None, now_us=1_000_250_000, period=1.0, now=10.5):
    axes = axes or status.Axes([])
    return {"url": "memq://", "daemons": [status.describe(s, 10.0, period, t, axes.of(s.machine), now, now_us)]}


def test_the_view_of_one_daemon():
    # five_axis_ac's axes: X Y Z in mm, Ap Cp in deg; 1 mm = 1000 µm, 1 deg = 3600 arcsec
    doc = _doc(_status(), _target([0.001, -0.0025, 0.0, 0.01, -1 / 3600]))
    d = doc["daemons"][0]
    assert [(a["axis"], a["unit"]) for a in d["last_target"]["correction"]] == [
        ("X", "um"), ("Y", "um"), ("Z", "um"), ("Ap", "arcsec"), ("Cp", "arcsec")]
    assert [a["value"] for a in d["last_target"]["correction"]] == pytest.approx([1.0, -2.5, 0.0, 36.0, -1.0])
    assert d["last_target"]["command_age_s"] == pytest.approx(0.25)
    assert d["status_age_s"] == pytest.approx(0.5) and d["instance"] == "0000000000001234"
    assert d["rejected"]["out of limits"] == 2 and d["rejected"]["step too large"] == 1
    text = status.render_text(doc)
    assert text.startswith("1 chaincompd on memq://\n")
    assert "five_axis_ac  instance 0000000000001234  enabled  up 12.5 s  status 0.5 s ago" in text
    assert "rejected 3 (out of limits 2, step too large 1)  clamped 0 (held back 0)  clamped input 0" in text
    assert "p50 12.3 µs  p99 45.0 µs  p99.9 2.50 ms  max 2.60 ms  (last 97 commands)" in text
    assert "correction X +1.000 µm  Y -2.500 µm  Z +0.000 µm  Ap +36.000 arcsec  Cp -1.000 arcsec" in text
    assert "last command seq 97, 0.25 s ago [compensating]" in text


@pytest.mark.parametrize("kw, state", [
    ({"ramp": 0.25}, "ramping 25%"), ({"compensating": False, "ramp": 0.0}, "disabled"),
    ({"final": True}, "exited")])
def test_states(kw, state):
    assert f"instance 0000000000001234  {state}  up" in status.render_text(_doc(_status(**kw), None))


def test_a_daemon_that_stops_publishing_is_silent():
    # heard at 10.0 s with a 1 s period: silent once 3 periods and the margin have passed
    assert _doc(_status(), None, now=13.4)["daemons"][0]["state"] == "enabled"
    assert _doc(_status(), None, now=13.6)["daemons"][0]["state"] == "silent"
    assert _doc(_status(), None, now=99.0, period=None)["daemons"][0]["state"] == "enabled"   # one status heard
    assert _doc(_status(final=True), None, now=99.0)["daemons"][0]["state"] == "exited"


def test_an_unknown_machine_keeps_wire_units(tmp_path):
    doc = _doc(_status(machine="no_such_machine"), _target([0.5, 2.0], machine="no_such_machine"))
    assert "correction #0 +0.500 mm|deg  #1 +2.000 mm|deg" in status.render_text(doc)
    assert "last command: none heard while listening" in status.render_text(_doc(_status(), None))
    for odd in ("", "../machines/five_axis_ac", "five_axis_ac\0x"):   # names off the bus are not paths
        assert status.Axes([]).of(odd) is None
    assert "latency   no command published yet" in status.render_text(_doc(_status(window=0), None))


def test_a_machine_file_names_axes_in_its_units(tmp_path):
    # a copy of five_axis_ac whose Z is commanded in µm: 0.5 on the wire is 0.5 µm
    text = open(machine_path("five_axis_ac")).read().replace("name: five_axis_ac", "name: um_z", 1)
    text = text.replace("{name: Z,  role: axis, unit: mm,  limits: [-400, 0]",
                        "{name: Z,  role: axis, unit: um,  limits: [-400000, 0]")
    path = tmp_path / "um_z.yaml"
    path.write_text(text)
    axes = status.Axes([str(path)])
    doc = _doc(_status(machine="um_z"), _target([0.0, 0.0, 0.5, 0.0, 0.0], machine="um_z"), axes)
    assert "Z +0.500 µm" in status.render_text(doc)


def _live(monkeypatch, tty: bool, frames: int = 2, fmt: str = "text") -> str:
    """The live loop on a captured console over memq:// (no daemon), stopped by Ctrl-C."""
    out = io.StringIO()
    out.isatty = lambda: tty
    monkeypatch.setattr(sys, "stdout", out)
    calls = []

    def listen(self, seconds):
        if len(calls) == frames:
            raise KeyboardInterrupt
        calls.append(seconds)
    monkeypatch.setattr(status.Bus, "listen", listen)
    args = argparse.Namespace(url="memq://", once=False, format=fmt, timeout=1.0, refresh=0.2, machines=[],
                              machine_option=[])
    with pytest.raises(KeyboardInterrupt):
        status.run(args)
    assert calls == [0.2] * frames
    return out.getvalue()


def test_live_view_without_a_terminal_prints_plain_frames(monkeypatch):
    out = _live(monkeypatch, tty=False)
    assert out == "no chaincompd heard on memq://\n" * 2 and "\x1b" not in out


def test_live_json_is_one_document_per_line(monkeypatch):
    out = _live(monkeypatch, tty=True, frames=3, fmt="json")
    assert out.splitlines() == ['{"url":"memq://","daemons":[]}'] * 3


def test_twins_name_each_other():
    text = status.render_text(_doc(_status(foreign_targets=5, foreign_instance=0xABC), None))
    assert "own heard back 0  foreign 5 (last from instance 0000000000000abc)" in text


def test_live_view_redraws_in_place_and_gives_the_cursor_back(monkeypatch):
    out = _live(monkeypatch, tty=True)
    frame = "\x1b[Hno chaincompd heard on memq://\x1b[K\n\x1b[J"
    assert out == "\x1b[?25l\x1b[2J" + frame * 2 + "\x1b[?25h\n"


def test_once_without_daemons_is_no_answer():
    proc = run_cli("status", "--once", "--url", "memq://", "--timeout", "0.1", "--format", "json", check=False)
    # exit 4, no answer (docs/reference/grammar.md), and in JSON mode the error object on stdout
    line = "chaincomp status: error: no chaincompd heard on memq:// within 0.1 s"
    assert proc.returncode == 4 and proc.stderr == line + "\n"
    assert json.loads(proc.stdout) == {"error": {"verb": "status", "kind": "no answer", "exit": 4, "message": line}}


@pytest.mark.parametrize("args, line", [
    (["--url", "bogus://x"], "chaincomp status: error: --url: cannot open LCM at 'bogus://x'"),
    (["--timeout", "0"], "argument --timeout: must be"),
    (["--refresh", "nan"], "argument --refresh:"),
    (["--format", "xml"], "argument --format: invalid choice"),
    (["/nonexistent/m.yaml"], "m.yaml"),
])
def test_refusals_are_one_line(args, line):
    # memq:// (in-process) unless the case gives its own: never udpm outside a namespace
    proc = run_cli("status", "--once", "--url", "memq://", "--timeout", "0.1", *args, check=False)
    assert proc.returncode == 2 and line in proc.stderr, proc.stderr
    assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr and proc.stdout == ""


@pytest.mark.slow
@needs_netns
def test_status_against_daemons_in_a_namespace():
    proc = subprocess.run([os.path.join(ROOT, "tests", "e2e", "netns.sh"), os.path.join(ROOT, ".venv", "bin", "python"),
                           "tests/e2e/e2e_status.py"], capture_output=True, text=True, cwd=ROOT, timeout=120)
    print(proc.stdout)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout.count("status --once shows the final counters") == 2


def test_the_limits_counters():
    # clamped targets, those of them held back towards none (docs/guide/daemon.md, "Truthful targets"), and
    # commands clamped into limits: each field of the status message in its place
    s = _status(clamped=12, held_back=5, clamped_input=3)
    d = _doc(s, None)["daemons"][0]
    assert (d["counters"]["clamped"], d["counters"]["held_back"], d["counters"]["clamped_input"]) == (12, 5, 3)
    assert "  clamped 12 (held back 5)  clamped input 3\n" in status.render_text(_doc(s, None))
    # the message carries it on the wire: encoded, decoded, shown
    again = T.lcmt_chaincomp_status.decode(s.encode())
    assert again.held_back == 5 and _doc(again, None)["daemons"][0]["counters"]["held_back"] == 5


def test_bus_text_reaches_the_terminal_escaped():
    # ECMA-48's control functions: C0 (0x00-0x1f), DEL and C1 (0x80-0x9f); with the bidi
    # overrides (U+202E) they move the cursor, retitle the window or reorder what is shown
    hostile = "five\x1b]0;owned\x07\x08\r\x9b2J\u202eaxis\\x1b"
    s = T.lcmt_chaincomp_status.decode(_status(machine=hostile).encode())   # as it comes off the bus
    text = status.render_text(_doc(s, None))
    assert not any(ord(c) < 0x20 and c != "\n" or 0x7f <= ord(c) <= 0x9f or c == "\u202e" for c in text)
    # every character still shown, the backslash as well, so no escape passes for another
    assert "five\\x1b]0;owned\\x07\\x08\\x0d\\x9b2J\\u202eaxis\\x5cx1b  instance" in text


def test_control_messages_are_counted():
    text = status.render_text(_doc(_status(control_received=7, control_refused=2), None))
    assert "(0 deep)  control messages 7 (refused 2)\n" in text
    assert "control messages" not in status.render_text(_doc(_status(), None))


def test_every_command_accounted_for_and_the_waiting():
    # 100 received: 96 published, 1 unpublished, 3 rejected; 42 missing by seq, 40 of them dropped
    # at the daemon's full queue (the other 2 in the kernel); the receipt-to-publish latency beside
    # the compute time
    s = _status(published=96, unpublished=1, seq_gaps=2, seq_missing=42, queue_dropped=40, control_queue_dropped=5,
                params_queue_dropped=1, readings_queue_dropped=2, targets_queue_dropped=3, oversized=4,
                queue_capacity=10000, control_queue_capacity=1000, lcm_queue_capacity=100000,
                receipt_p50_ns=1_500_000, receipt_p99_ns=250_000_000, receipt_max_ns=300_000_000)
    d = _doc(s, None)["daemons"][0]
    c = d["counters"]
    assert c["received"] == c["published"] + c["unpublished"] + sum(d["rejected"].values())
    assert d["queues"] == {"commands": {"capacity": 10000, "dropped": 40}, "control": {"capacity": 1000, "dropped": 5},
                           "params": {"dropped": 1}, "readings": {"dropped": 2}, "targets": {"dropped": 3},
                           "oversized": 4, "lcm": {"capacity": 100000, "found_full": 0}}
    assert d["receipt_latency_ns"] == {"p50": 1_500_000, "p99": 250_000_000, "max": 300_000_000}
    text = status.render_text(_doc(s, None))
    assert "rejected 3 (out of limits 2, step too large 1)  unpublished 1  clamped" in text
    assert "seq gaps 2 (42 missing)" in text and "queue dropped 40 (10000 deep)" in text
    assert ("queues    dropped: control 5  params 1  readings 2  targets 3  oversized 4  LCM's found full 0 times\n"
            in text)
    assert "p50 12.3 µs  p99 45.0 µs" in text and "receipt to publish p50 1.50 ms  p99 250.00 ms" in text
    # LCM's queue found full: LCM may have discarded messages uncounted, and the view says so
    text = status.render_text(_doc(_status(lcm_queue_full=2), None))
    assert "LCM's found full 2 times  (drops not exact)\n" in text


def test_the_targets_and_the_objective_before_and_after():
    """Counts by what the targets correct and the objective's RMS as a length: 97 targets whose
    commands scored (4 µm)^2 each and the targets (1 µm)^2, worked out by hand."""
    s = _status(targets_full=90, targets_partial=5, targets_uncorrected=2, targets_worse=0,
                objective_before=97 * 0.004 ** 2, objective_after=97 * 0.001 ** 2, direction_weight=100.0)
    d = _doc(s, None)["daemons"][0]
    assert d["objective"] == {"direction_weight_mm": 100.0, "full": 90, "partial": 5, "uncorrected": 2, "worse": 0,
                              "before_sum_mm2": 97 * 0.004 ** 2, "after_sum_mm2": 97 * 0.001 ** 2}
    text = status.render_text(_doc(s, None))
    assert ("  corrects  full 90  partial 5  uncorrected 2  worse than the command 0  "
            "objective RMS 4 µm -> 1 µm (direction at 100 mm)") in text
