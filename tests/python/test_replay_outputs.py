"""The replay binary (build/bin/chaincomp_replay, behind chaincomp replay, which checks the
same) refuses one file for both its outputs (the log and the CSV would be written interleaved
into it), before it writes anything."""

import os
import subprocess

import pytest

from conftest import PARAMS, ROOT, machine_path, run_cli

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
