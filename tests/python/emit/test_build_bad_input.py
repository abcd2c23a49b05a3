"""chaincomp build's bad input: the library never overwrites its machine file, an empty output
folder is refused before compiling."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from helpers import ROOT, VMC, refused


@pytest.mark.slow
def test_build_never_copies_the_library_over_its_machine_file(tmp_path):
    # build M -o DIR writes DIR/NAME.so: a machine file of that very name was overwritten by the library
    m = tmp_path / "tiny.so"
    text = ("name: tiny\nsymbols:\n  - {name: X, role: axis, unit: mm, limits: [-1, 1]}\n"
            "  - {name: EXX, role: error, unit: um}\nchain:\n  - {translate: [X + EXX, 0, 0]}\n"
            "tool:\n  point: [0, 0, 0]\n  direction: [0, 0, 1]\n")
    m.write_text(text, encoding="utf-8")
    env = dict(os.environ, XDG_CACHE_HOME=str(tmp_path / "cache"))
    res = subprocess.run([sys.executable, "-m", "chaincomp.cli.main", "build", str(m), "-o", str(tmp_path)],
                         capture_output=True, text=True, cwd=ROOT, timeout=300, env=env)
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
    last = res.stderr.strip().splitlines()[-1]   # after the build's progress lines
    assert last.startswith("chaincomp build: error: -o ") and "tiny.so" in last and "input" in last, last
    assert m.read_text(encoding="utf-8") == text


def test_build_refuses_an_empty_output_folder_before_compiling(capsys, monkeypatch, tmp_path):
    """build --linuxcnc -o '' compiled (minutes) and exited 0 without saying where it put the library."""
    import chaincomp.cli.build as verb

    def no_compile(*args, **kwargs):
        raise AssertionError("compiled before refusing the option")
    monkeypatch.setattr(verb, "build", no_compile)
    monkeypatch.setattr(verb, "build_linuxcnc", no_compile)
    refused(capsys, "build", VMC, "--linuxcnc", "-o", "", match="-o: an empty value (expected a folder)")
    refused(capsys, "build", VMC, "-o", " ", match="-o: an empty value (expected a folder)")
    refused(capsys, "build", VMC, "--linuxcnc", "--params", "",
             match="--params: an empty value (leave the option out for every error zero)")
