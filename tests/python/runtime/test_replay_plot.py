"""chaincomp simulate-log, replay and plot."""

import csv
import math
import os
import struct
import subprocess
import sys

import numpy as np

import pytest

from helpers import PARAMS, ROOT, machine_path, run_cli

sys.path.insert(0, os.path.join(ROOT, "tests", "e2e"))
E2E_CONFIG = os.path.join(ROOT, "tests", "e2e", "config_test.yaml")
FIVE = machine_path("five_axis_ac")
FIVE_PARAMS = os.path.join(PARAMS, "five_axis_ac-demo.yaml")


def _read_csv(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def _exact_errors(rows):
    """Largest point (mm) and direction (rad) error of actual-at-corrected vs nominal-at-commanded."""
    from common import exact_check
    names = ["X_mm", "Y_mm", "Z_mm", "Ap_deg", "Cp_deg"]
    cmd = np.array([[float(r["commanded_" + n]) for n in names] for r in rows])
    cor = np.array([[float(r["corrected_" + n]) for n in names] for r in rows])
    return exact_check(cmd, cor)


@pytest.mark.slow
def test_replay_matches_the_exact_model_on_every_record(tmp_path):
    log, out, table = tmp_path / "axes.lcmlog", tmp_path / "corrected.lcmlog", tmp_path / "replay.csv"
    run_cli("simulate-log", FIVE, "-o", str(log), "--seconds", "2")
    proc = run_cli("replay", FIVE, str(log), "--params", FIVE_PARAMS, "--config", E2E_CONFIG,
                   "-o", str(out), "--csv", str(table))
    assert "2000 commands on CHAINCOMP_COMMAND, 2000 corrected, 0 rejected" in proc.stderr
    rows = _read_csv(table)
    assert len(rows) == 2000 and all(r["result"] == "ok" for r in rows)
    dp, dd = _exact_errors(rows)
    assert dp < 1e-6 and dd < 1e-9, (dp, dd)
    # the corrected log holds the originals plus one target per command, timestamps kept
    import lcm
    events = list(lcm.EventLog(str(out), "r"))
    assert [e.channel for e in events].count("CHAINCOMP_CORRECTED") == 2000
    originals = {e.timestamp for e in lcm.EventLog(str(log), "r")}
    assert {e.timestamp for e in events if e.channel == "CHAINCOMP_CORRECTED"} == originals


@pytest.mark.slow
def test_replay_reports_exactly_the_corrupted_records(tmp_path):
    import lcm
    from chaincomp.emit.buildtree import import_lcmtypes
    log, bad, table = tmp_path / "axes.lcmlog", tmp_path / "bad.lcmlog", tmp_path / "replay.csv"
    run_cli("simulate-log", FIVE, "-o", str(log), "--seconds", "0.5")
    types = import_lcmtypes()
    corrupt = {10: "undecodable", 50: "non_finite", 120: "undecodable", 300: "wrong_axis_count"}
    out = lcm.EventLog(str(bad), "w", overwrite=True)
    for e in lcm.EventLog(str(log), "r"):
        data = e.data
        if e.eventnum in corrupt:
            msg = types.lcmt_axis_command.decode(data)
            if corrupt[e.eventnum] == "non_finite":
                msg.axes = [float("nan")] + list(msg.axes[1:])
                data = msg.encode()
            elif corrupt[e.eventnum] == "wrong_axis_count":
                msg.num_axes = 4
                data = msg.encode()
            else:
                data = data[:8] + struct.pack(">q", 0)[:3]  # truncated
        out.write_event(e.timestamp, e.channel, data)
    out.close()
    proc = run_cli("replay", FIVE, str(bad), "--params", FIVE_PARAMS, "--config", E2E_CONFIG,
                   "--csv", str(table))
    rows = _read_csv(table)
    rejected = {int(r["event"]): r["result"] for r in rows if r["result"] != "ok"}
    assert rejected == corrupt
    for event, reason in corrupt.items():
        assert f"event {event} " in proc.stderr and reason in proc.stderr
    assert "496 corrected, 4 rejected" in proc.stderr


@pytest.mark.slow
def test_replay_skips_and_reports_damaged_stretches_of_a_log(tmp_path):
    """Framing damage (garbage between events, a broken length, a truncated last event): each
    stretch is reported with its byte range and the events around it are still replayed."""
    log, bad = tmp_path / "axes.lcmlog", tmp_path / "bad.lcmlog"
    run_cli("simulate-log", FIVE, "-o", str(log), "--seconds", "0.1")
    raw = log.read_bytes()
    sync = b"\xed\xa1\xda\x01"
    starts = [i for i in range(len(raw)) if raw.startswith(sync, i)]
    assert len(starts) == 100
    size = starts[1] - starts[0]
    garbage = b"\x00junk\x01" * 3  # 18 bytes without a sync word
    broken = bytearray(raw[starts[40]:starts[41]])
    broken[20:24] = struct.pack(">i", -5)  # channel length
    damaged = (raw[:starts[10]] + garbage + raw[starts[10]:starts[40]] + bytes(broken)
               + raw[starts[41]:starts[99]] + raw[starts[99]:starts[99] + size // 2])
    bad.write_bytes(damaged)
    proc = run_cli("replay", FIVE, str(bad), "--params", FIVE_PARAMS, "--config", E2E_CONFIG)
    g = starts[10]
    assert f"bytes {g}-{g + len(garbage) - 1} of the log skipped: no sync word" in proc.stderr
    b = starts[40] + len(garbage)
    assert f"bytes {b}-{b + size - 1} of the log skipped: invalid channel or data length" in proc.stderr
    t = len(damaged) - size // 2
    assert f"bytes {t}-{len(damaged) - 1} of the log skipped: event length runs past the end of the log" in proc.stderr
    assert "98 events, 98 commands on CHAINCOMP_COMMAND, 98 corrected, 0 rejected" in proc.stderr
    assert "damaged: 3 stretches of the log" in proc.stderr


@pytest.mark.slow
def test_replay_reports_one_damaged_stretch_once(tmp_path):
    """Garbage straight before an event with a broken length is one stretch, and a tail that
    holds sync words but no whole event is one stretch to the end."""
    log, bad = tmp_path / "axes.lcmlog", tmp_path / "bad.lcmlog"
    run_cli("simulate-log", FIVE, "-o", str(log), "--seconds", "0.02")
    raw = log.read_bytes()
    sync = b"\xed\xa1\xda\x01"
    starts = [i for i in range(len(raw)) if raw.startswith(sync, i)]
    broken = bytearray(raw[starts[5]:starts[6]])
    broken[24:28] = struct.pack(">i", -1)  # data length
    tail = b"zz" + sync + b"\x00" * 4 + sync + b"\x01"
    damaged = raw[:starts[5]] + b"junk" + bytes(broken) + raw[starts[6]:] + tail
    bad.write_bytes(damaged)
    proc = run_cli("replay", FIVE, str(bad), "--params", FIVE_PARAMS, "--config", E2E_CONFIG)
    a, b = starts[5], starts[6] + 4 - 1
    assert f"bytes {a}-{b} of the log skipped: no sync word" in proc.stderr
    t = len(raw) + 4
    assert f"bytes {t}-{len(damaged) - 1} of the log skipped: truncated event at the end of the log" in proc.stderr
    assert proc.stderr.count("of the log skipped") == 2
    assert "19 events, 19 commands" in proc.stderr and "damaged: 2 stretches" in proc.stderr


@pytest.mark.slow
def test_replay_refuses_to_write_over_its_input(tmp_path):
    log = tmp_path / "axes.lcmlog"
    run_cli("simulate-log", FIVE, "-o", str(log), "--seconds", "0.01")
    before = log.read_bytes()
    os.symlink(log, tmp_path / "link.lcmlog")
    for flag, target in (("-o", log), ("--csv", tmp_path / "link.lcmlog")):
        proc = run_cli("replay", FIVE, str(log), "--params", FIVE_PARAMS, flag, str(target), check=False)
        assert proc.returncode == 2 and f"{flag} {target}: is also an input ({log})" in proc.stderr, proc.stderr
        # the binary itself refuses too (called directly, as a controller integration may)
        proc = subprocess.run([os.path.join(ROOT, "build", "bin", "chaincomp_replay"), "--machine", FIVE,
                               "--params", FIVE_PARAMS, "--in", str(log), "--out" if flag == "-o" else flag,
                               str(target)], capture_output=True, text=True, timeout=120)
        assert proc.returncode == 2 and f"{target}: is the input log itself" in proc.stderr, proc.stderr
    assert log.read_bytes() == before


@pytest.mark.slow
def test_replay_bad_input(tmp_path):
    proc = run_cli("replay", FIVE, str(tmp_path / "none.lcmlog"), "--params", FIVE_PARAMS,
                   check=False)
    assert proc.returncode == 2 and "none.lcmlog: no such log file" in proc.stderr
    notlog = tmp_path / "x.lcmlog"
    notlog.write_bytes(b"not a log")
    proc = run_cli("replay", FIVE, str(notlog), "--params", str(tmp_path / "p.yaml"), check=False)
    assert proc.returncode == 2 and "p.yaml: cannot read file" in proc.stderr


@pytest.mark.slow
def test_fig3_map_equals_an_independent_first_order_model(tmp_path):
    """The paper's Fig. 3: first-order dy over Ap, Cp in -60..60 deg with its stated values."""
    from chaincomp import load_machine
    from chaincomp.cli.plot import error_grid
    from chaincomp.cli.common import values_for
    m = load_machine(machine_path("angle_head"))
    values, _ = values_for(m, os.path.join(PARAMS, "angle_head-fig3.yaml"), [])
    g1, g2, z = error_grid(m, values, ("Ap", "Cp"), ((-60, 60), (-60, 60)), 25, "dy", "first")

    # Independent: the §3.2 chain as numpy matrices, first-order part by the complex step.
    G, Yp, e = 20.0, math.radians(50), 10.0
    arc = math.pi / 648000
    err = {"Ocx": 0.005, "Ocy": -0.015, "DY": 0.0, "ThetaAs": 100 * arc, "ThetaCh": 150 * arc,
           "ThetaCv": -50 * arc, "Oas": 0.0, "ThetaAv": 0.0}

    def R(axis, t):
        c, s = np.cos(t), np.sin(t)
        i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
        M = np.eye(4, dtype=complex)
        M[i, i] = M[j, j] = c
        M[i, j], M[j, i] = -s, s
        return M

    def T(x, y, z_):
        M = np.eye(4, dtype=complex)
        M[:3, 3] = [x, y, z_]
        return M

    def y_of(A, C, v):  # main rotations left-handed (the paper's sense), errors right-handed
        X = (R("x", v["ThetaCv"]) @ R("y", v["ThetaCh"]) @ R("z", C) @ T(0, -e, -e / math.tan(Yp))
             @ T(v["Ocx"], v["Ocy"], 0) @ R("x", -Yp) @ R("z", -A) @ R("y", v["ThetaAv"]) @ R("x", -v["DY"])
             @ R("x", Yp) @ T(0, v["Oas"], 0) @ R("y", -v["ThetaAs"]) @ T(0, 0, -G) @ np.array([0, 0, 0, 1]))
        return X[1]

    h = 1e-30
    want = np.zeros_like(z)
    for a, A in enumerate(np.radians(g1)):
        for c, C in enumerate(np.radians(g2)):
            for name, value in err.items():
                if value:
                    step = {k: 0.0 for k in err}
                    step[name] = 1j * h
                    want[a, c] += value * np.imag(y_of(A, C, step)) / h
    assert np.allclose(z, want, rtol=0, atol=1e-12)

    png = tmp_path / "fig3.png"
    run_cli("plot", machine_path("angle_head"), "--params", os.path.join(PARAMS, "angle_head-fig3.yaml"),
            "--component", "dy", "--over", "Ap,Cp", "--range", "-60:60", "-o", str(png))
    with open(png, "rb") as f:
        head = f.read(24)
    assert head[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", head[16:24])
    # an 800 x 600 canvas cropped to the drawing (bbox_inches="tight"): cropped, never emptied
    assert 560 <= width <= 800 and 420 <= height <= 600, (width, height)


@pytest.mark.slow
def test_plot_bad_input(tmp_path):
    proc = run_cli("plot", machine_path("angle_head"), "--over", "Ap,Zz", "-o", str(tmp_path / "x.png"), check=False)
    assert proc.returncode == 2 and "--over expects two different axes of angle_head (Ap, Cp), got 'Ap,Zz'" in proc.stderr
    proc = run_cli("plot", machine_path("angle_head"), "--range", "5:1", "-o", str(tmp_path / "x.png"), check=False)
    assert proc.returncode == 2 and "LO must be below HI" in proc.stderr
    proc = run_cli("plot", "--replay", str(tmp_path / "none.csv"), "-o", str(tmp_path / "x.png"), check=False)
    assert proc.returncode == 2 and "none.csv: cannot read" in proc.stderr
