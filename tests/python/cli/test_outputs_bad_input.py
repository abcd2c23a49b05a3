"""Every verb's outputs: an empty name refused before any work, a figure on a full device or a
write that fails midway named in one line with the old file left whole (pipes, links, full
devices and read-only folders for every output of every verb: test_every_output.py)."""

from __future__ import annotations

import pytest

from helpers import M4, URDF, VMC, cli, m4_nominal_rows, machine_path, refused, write_file


# ----------------------------------------------------------------------------- empty -o and --params

@pytest.mark.parametrize("argv", [
    ["protocol", machine_path("panda"), "--poses", "30", "-o"],        # designed 30 poses, wrote nothing
    ["identify", VMC, "MEAS", "-o"],
    ["simulate-measurements", VMC, "-o"],
    ["testvectors", VMC, "-o"],
    ["report", VMC, "-o"],
    ["budget", VMC, "--plot"],
])
@pytest.mark.parametrize("value", ["", "  "])
def test_an_empty_output_is_refused_before_any_work(capsys, monkeypatch, tmp_path, measurements, argv, value):
    import chaincomp.cli.protocol as protocol

    def no_design(*args, **kwargs):
        raise AssertionError("designed the poses before refusing -o")
    monkeypatch.setattr(protocol, "design_poses", no_design)
    monkeypatch.chdir(tmp_path)
    argv = [measurements if a == "MEAS" else a for a in argv]
    refused(capsys, *argv, value, match=f"{argv[-1]}: an empty value (expected a file name)")
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- figures on a full disk

def _iso_runs(tmp_path) -> str:
    path = tmp_path / "runs.csv"
    rows = [f"{t},{j},{d},{0.1 * j + (0.5 if d == 'up' else -0.5)}"
            for j in (1, 2, 3) for d in ("up", "down") for t in (0, 100, 200)]
    path.write_text("target [mm],run,direction,deviation [um]\n" + "\n".join(rows) + "\n")
    return str(path)


@pytest.mark.slow
@pytest.mark.parametrize("verb", ["budget", "iso230-2"])
def test_a_figure_on_a_full_disk_is_an_error_naming_the_file(capsys, monkeypatch, tmp_path, verb):
    """fig.savefig straight onto /dev/full raised OSError: exit 3. /dev/full takes the open and
    refuses every write (ENOSPC) to anyone; the up-front check_image (which as root passes it
    anyway) is skipped so that the write itself fails."""
    import importlib
    module = importlib.import_module(f"chaincomp.cli.{verb.replace('-', '_')}")
    monkeypatch.setattr(module, "check_image", lambda *args, **kwargs: None)
    argv = [verb, VMC, "--set", "EXX=1", "--grid", "2"] if verb == "budget" else [verb, _iso_runs(tmp_path)]
    refused(capsys, *argv, "--plot", "/dev/full",
             match=f"chaincomp {verb}: error: /dev/full: cannot write: No space left on device")

# A four-axis machine written the way a user would: X, Y, Z slides and a B table, one error block
# after each, a tool length L.


# ----------------------------------------------------------------------------- URDF


# ----------------------------------------------------------------------------- spreadsheet exports


# ----------------------------------------------------------------------------- a write that fails midway

def _outputs(tmp_path) -> dict[str, list[str]]:
    machine = write_file(tmp_path, "m.yaml", M4)
    meas = write_file(tmp_path, "meas.csv", "X,Y,Z,B,x,y,z\n" + "".join(",".join(r) + "\n" for r in m4_nominal_rows()))
    return {"import-urdf": ["import-urdf", write_file(tmp_path, "r.urdf", URDF), "--base", "base", "--tip", "tip"],
            "identify": ["identify", machine, meas, "--assume-zero", "EXB,EAX,EYY,EBB"],
            "simulate-measurements": ["simulate-measurements", machine],
            "simulate-log": ["simulate-log", machine, "--seconds", "0.01"],
            "report": ["report", machine],
            "testvectors": ["testvectors", machine, "--count", "2"]}


@pytest.mark.slow
@pytest.mark.parametrize("verb", ["simulate-measurements", "simulate-log", "report", "testvectors"])
def test_a_write_that_fails_midway_leaves_the_old_file_whole(tmp_path, verb):
    """A file size limit of 2 kB (RLIMIT_FSIZE, as a full disk would): the write fails partway.
    Before, simulate-measurements left the first 100 kB of its CSV (which identify reads as the
    whole run, a line short), and simulate-log exited 3 (an internal error)."""
    import resource
    import signal
    import subprocess
    import sys

    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (2000, 2000))
    argv = _outputs(tmp_path)[verb]
    if verb == "simulate-measurements":
        argv += ["--setups", "random:200"]
    if verb in ("testvectors", "simulate-log"):
        argv[-1] = {"testvectors": "100", "simulate-log": "1"}[verb]   # 100 vectors, 1000 records: past 2 kB
    out = tmp_path / "out.dat"
    out.write_text("old\n")
    proc = subprocess.run([sys.executable, "-m", "chaincomp.cli.main", *argv, "-o", str(out)], capture_output=True,
                          text=True, preexec_fn=limit)
    assert proc.returncode == 2, proc.stderr
    assert f"error: {out}: cannot write" in proc.stderr and "File too large" in proc.stderr
    assert out.read_text() == "old\n"
    import os
    assert not [f for f in os.listdir(tmp_path) if f.startswith(".")]   # no temporary file left
