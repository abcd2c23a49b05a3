"""`chaincomp replay --format json`: the replay's summary as one JSON object on standard output,
on a machine the test writes itself and a log the test builds record by record, so that every
count is known before the replay runs (the truth here is the log's construction and the CSV's
own rows, not the summary's text)."""

import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from helpers import ROOT

REPLAY = os.path.join(ROOT, "build", "bin", "chaincomp_replay")
pytestmark = pytest.mark.skipif(not os.path.exists(REPLAY), reason="build/bin/chaincomp_replay not built")

# Two slides, X on Y, with a squareness error, X's positioning error and its yaw.
MACHINE = """\
name: xy_own
length_unit: mm
rotation_sense: right_hand
error_block_order: txyz
symbols:
  - {name: X, role: axis, unit: mm, limits: [-100, 100]}
  - {name: Y, role: axis, unit: mm, limits: [-50, 50]}
  - {name: EC0Y, role: error, unit: arcsec}
  - {name: ECX, role: error, unit: arcsec}
  - {name: EXX, role: error, unit: um}
loop:
  tool:
    - {translate: [Y*sin(EC0Y), Y*cos(EC0Y), 0]}
    - {translate: [X, 0, 0]}
    - {errors: {dx: EXX, ez: ECX}}
  workpiece:
    - {translate: [0, 0, 0], label: table}
tool:
  point: [0, 0, 0]
  direction: [0, 0, 1]
"""
PARAMS = "machine: xy_own\nvalues:\n  EC0Y: 4 arcsec\n  ECX: -3 arcsec\n  EXX: 2 um\n"


def _log(tmp_path, commands):
    """A log of the test's own commands: (machine, axes) or raw bytes for an undecodable record."""
    import lcm
    from chaincomp.emit.buildtree import import_lcmtypes
    types = import_lcmtypes()
    path = tmp_path / "in.lcmlog"
    out = lcm.EventLog(str(path), "w", overwrite=True)
    for k, c in enumerate(commands):
        if isinstance(c, bytes):
            out.write_event(1000 * (k + 1), "CHAINCOMP_COMMAND", c)
            continue
        m = types.lcmt_axis_command()
        m.utime, m.seq, m.machine, m.num_axes = 1000 * (k + 1), k + 1, c[0], len(c[1])
        m.axes = list(c[1]) + [0.0] * (8 - len(c[1]))
        out.write_event(m.utime, "CHAINCOMP_COMMAND", m.encode())
    out.write_event(10**9, "SOMETHING_ELSE", b"not a command")   # an event, not a command
    out.close()
    return path


def _replay(tmp_path, log, *extra):
    machine = tmp_path / "xy_own.yaml"
    machine.write_text(MACHINE)
    params = tmp_path / "p.yaml"
    params.write_text(PARAMS)
    return subprocess.run([sys.executable, "-m", "chaincomp.cli.main", "replay", str(machine),
                           str(log), "--params", str(params), *extra], capture_output=True, text=True,
                          timeout=300, cwd=tmp_path)


@pytest.mark.slow
def test_replay_json_counts_what_the_log_holds(tmp_path):
    # a circle, 1.6 mm at most between commands (max_step is 10 mm): every good command corrected
    good = [("xy_own", (80 * math.cos(k / 50), 40 * math.sin(k / 50))) for k in range(200)]
    commands = good[:100] + [b"\x01\x02garbage"] * 3 + [("other_machine", (0.0, 0.0))] * 2 \
        + [("xy_own", (math.nan, 0.0))] + good[100:]
    log = _log(tmp_path, commands)
    csv = tmp_path / "out.csv"
    proc = _replay(tmp_path, log, "--csv", str(csv), "--format", "json")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["machine"] == "xy_own" and summary["channel"] == "CHAINCOMP_COMMAND"
    assert summary["events"] == len(commands) + 1 and summary["commands"] == len(commands)
    rejected = {k: v for k, v in summary["rejected"].items() if v}
    assert summary["rejected_total"] == 6 == sum(rejected.values()), rejected
    assert rejected.get("undecodable") == 3, rejected
    assert summary["corrected"] == 200
    assert summary["damaged"] == {"stretches": 0, "bytes": 0}
    # the corrections against the CSV's own rows
    header = csv.read_text().splitlines()[0].split(",")
    rows = [line.split(",") for line in csv.read_text().splitlines()[1:]]
    ok = [r for r in rows if r[3] == "ok"]
    assert len(ok) == 200
    for axis in summary["correction"]:
        col = header.index(f"correction_{axis['axis']}_{axis['unit']}")
        values = np.array([float(r[col]) for r in ok])
        assert axis["max_abs"] == pytest.approx(np.abs(values).max(), rel=1e-12)
        assert axis["rms"] == pytest.approx(np.sqrt(np.mean(values ** 2)), rel=1e-12)
    # EXX and the squareness (Y sin EC0Y) move the tool in x: X is corrected (by microns)
    assert [a["axis"] for a in summary["correction"]] == ["X", "Y"]
    assert 1e-4 < summary["correction"][0]["max_abs"] < 1e-2


def test_replay_text_summary_stays_on_stderr(tmp_path):
    log = _log(tmp_path, [("xy_own", (10.0, 20.0))] * 5)
    proc = _replay(tmp_path, log)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == ""
    assert "5 commands on CHAINCOMP_COMMAND, 5 corrected, 0 rejected" in proc.stderr


def test_replay_format_refused_in_one_line(tmp_path):
    log = _log(tmp_path, [("xy_own", (0.0, 0.0))])
    proc = subprocess.run([REPLAY, "--machine", "m.yaml", "--params", "p.yaml", "--in", str(log), "--format", "xml"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines()[-1] == "chaincomp replay: error: --format xml: expected text or json"
