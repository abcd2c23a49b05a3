"""The replay binary (build/bin/chaincomp_replay, behind chaincomp replay, which checks the
same) refuses one file for both its outputs (the log and the CSV would be written interleaved
into it), before it writes anything; and its summary counts the corrections the limits held
back, as many as its CSV shows."""

import os
import re
import subprocess

import pytest

from helpers import PARAMS, ROOT, machine_path, run_cli

REPLAY = os.path.join(ROOT, "build", "bin", "chaincomp_replay")

FIVE = machine_path("five_axis_ac")
FIVE_PARAMS = os.path.join(PARAMS, "five_axis_ac-demo.yaml")


@pytest.mark.skipif(not os.path.exists(REPLAY), reason="build/bin/chaincomp_replay not built")
def test_replay_refuses_the_same_file_for_out_and_csv(tmp_path):
    log = tmp_path / "axes.lcmlog"
    run_cli("simulate-log", FIVE, "-o", str(log), "--seconds", "0.01")
    out = tmp_path / "out.dat"
    for csv, existing in ((out, False), (tmp_path / "link.dat", True)):
        if existing:  # another spelling of a file that is there: a link to it
            out.write_bytes(b"keep")
            os.symlink(out, csv)
        proc = subprocess.run([REPLAY, "--machine", FIVE, "--params", FIVE_PARAMS, "--in", str(log),
                               "--out", str(out), "--csv", str(csv)], capture_output=True, text=True, timeout=120)
        assert proc.returncode == 2, proc.stderr
        assert proc.stderr.strip().splitlines()[-1].startswith("chaincomp replay: error: --csv: "), proc.stderr
        assert out.read_bytes() == b"keep" if existing else not out.exists()


@pytest.mark.skipif(not os.path.exists(REPLAY), reason="build/bin/chaincomp_replay not built")
def test_replay_counts_the_corrections_held_back(tmp_path):
    """The stream of tests/cpp/held_back_case.hpp: five_axis_ac held at A = 1 deg (the tool
    nearly along C, where the tilt errors ask for a C correction beyond max_correction), then
    A opened by 5 deg a command to 46 deg, where that C correction swings the tool far and the
    rate limit (0.001 deg a command) unwinds it slowly. Where the daemon holds a correction
    back it publishes the previous one shrunk by exactly one rate step towards none (docs/guide/daemon.md,
    "Truthful targets"): the CSV shows each such target, and the summary must count as many."""
    import lcm
    import numpy as np
    import yaml
    from chaincomp.emit.buildtree import import_lcmtypes
    from chaincomp.model.machine import load_machine
    types = import_lcmtypes()
    machine = load_machine(FIVE)
    # 20 um and 20 arcsec on every error, alternating signs by the symbol's place (as the C++ case)
    values = {s.name: f"{20 if i % 2 == 0 else -20} {'um' if s.unit.kind == 'length' else 'arcsec'}"
              for i, s in enumerate(machine.symbols) if s.role == "error"}
    params = tmp_path / "p.yaml"
    params.write_text(yaml.safe_dump({"machine": "five_axis_ac", "values": values}))
    config = tmp_path / "r.yaml"
    config.write_text("ramp_time: 0\n")   # compensating in full from the first command
    log = tmp_path / "axes.lcmlog"
    out = lcm.EventLog(str(log), "w", overwrite=True)
    for k in range(3001):
        m = types.lcmt_axis_command()
        m.utime, m.seq, m.machine, m.num_axes = 1000 * (k + 1), k + 1, "five_axis_ac", 5
        m.axes = [100.0, -20.0, -150.0, 1.0 if k < 1000 else min(46.0, 1.0 + 5.0 * (k - 999)), 30.0, 0.0, 0.0, 0.0]
        out.write_event(m.utime, "CHAINCOMP_COMMAND", m.encode())
    out.close()
    csv = tmp_path / "out.csv"
    proc = subprocess.run([REPLAY, "--machine", FIVE, "--params", str(params), "--config", str(config),
                           "--in", str(log), "--csv", str(csv)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    counted = re.search(r"^  clamped (\d+) \((\d+) held back towards none\), commands clamped into limits (\d+)$",
                        proc.stderr, re.M)
    assert counted, proc.stderr
    clamped, held, clamped_input = map(int, counted.groups())
    header = csv.read_text().splitlines()[0].split(",")
    rows = np.loadtxt(csv, delimiter=",", skiprows=1, usecols=range(4, len(header)))
    cols = [i - 4 for i, name in enumerate(header) if name.startswith("correction_")]
    correction = rows[:, cols]
    prev = np.vstack([np.zeros(5), correction[:-1]])
    step = 0.001   # max_correction_step of every axis (configs/runtime/default.yaml)
    largest = np.abs(prev).max(axis=1)
    shrunk = prev * (1 - np.minimum(1.0, step / np.where(largest > 0, largest, 1.0)))[:, None]
    held_back = (largest > step) & (np.abs(correction - shrunk).max(axis=1) <= 1e-9)
    assert held_back.sum() > 100
    assert held == held_back.sum(), (held, np.flatnonzero(held_back))
    assert clamped > held and clamped_input == 0
    # and none before A opened: held back only where the old correction had become wrong
    assert np.flatnonzero(held_back).min() > 1000
