"""The model cache is checked before it is trusted (design §11, issue #38 item 6): chaincomp build
records the SHA-256 of each library it compiles (NAME.so.sha256, sha256sum's format) and
checks it before saying "cached"; chaincompd and replay check it before dlopen. A library
truncated, overwritten with garbage or with another machine's valid library was reported
"cached" and crashed (SIGBUS, SIGILL) or refused every later start until the folder was
deleted by hand; now it is built again, by either side.

The truths: coreutils' sha256sum reads the record (`sha256sum -c`), the library's own entry
point names its machine (model_library.hpp, read with ctypes), and a replay through the rebuilt
library corrects the commands.
"""

from __future__ import annotations

import ctypes
import glob
import os
import shutil
import subprocess

import numpy as np
import pytest

from test_build import CONFIG_TEXT, _Library, chaincomp, params_of, variant

CORRUPTIONS = {
    "truncated": lambda path, other: _write(path, _read(path)[:4096]),
    "garbage": lambda path, other: _write(path, bytes(range(256)) * (len(_read(path)) // 256)),
    "another valid library": lambda path, other: _write(path, _read(other)),
}


def _read(path):
    with open(path, "rb") as f:
        return f.read()


def _write(path, data):   # in place, as a full disk, a copy or an editor would leave it
    with open(path, "r+b") as f:
        f.write(data)
        f.truncate()


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    folder = tmp_path_factory.mktemp("machines")
    env = dict(os.environ, XDG_CACHE_HOME=str(tmp_path_factory.mktemp("cache")))
    paths = {}
    for name, h in (("cache_trunnion", 430), ("cache_other", 420)):
        machine = variant(folder, name, h)
        proc = chaincomp(env, "build", machine)
        assert proc.returncode == 0, proc.stderr
        paths[name] = (machine, proc.stdout.strip())
    return {"env": env, "paths": paths}


def _built(env, machine: str) -> str:
    """The library of ``machine`` in the cache now (built if the toolchain's key changed since)."""
    proc = chaincomp(env, "build", machine)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout.strip()


def _intact(library: str, name: str) -> None:
    """sha256sum accepts the record, and the library is the model of ``name``."""
    proc = subprocess.run(["sha256sum", "-c", os.path.basename(library) + ".sha256"], capture_output=True, text=True,
                          cwd=os.path.dirname(library))
    assert proc.returncode == 0 and proc.stdout == f"{os.path.basename(library)}: OK\n", proc.stdout + proc.stderr
    copy = library + f".{os.getpid()}.check.so"   # its own name: ctypes does not reload a path it has open
    shutil.copy(library, copy)
    try:
        lib = ctypes.CDLL(copy)
        lib.chaincomp_model_library.restype = ctypes.POINTER(_Library)
        assert lib.chaincomp_model_library().contents.name.decode() == name
    finally:
        os.unlink(copy)


@pytest.mark.slow
def test_build_records_the_digest_sha256sum_reads(cache):
    for name, (_, library) in cache["paths"].items():
        _intact(library, name)
    proc = chaincomp(cache["env"], "build", cache["paths"]["cache_trunnion"][0])
    assert proc.returncode == 0 and proc.stderr.endswith(": cached\n") and "compiled in" not in proc.stderr, proc.stderr


@pytest.mark.slow
@pytest.mark.parametrize("how", list(CORRUPTIONS))
def test_build_rebuilds_a_changed_library(cache, how):
    machine = cache["paths"]["cache_trunnion"][0]
    library = _built(cache["env"], machine)
    CORRUPTIONS[how](library, _built(cache["env"], cache["paths"]["cache_other"][0]))
    proc = chaincomp(cache["env"], "build", machine)
    assert proc.returncode == 0, proc.stderr
    assert "building it again" in proc.stderr and "compiled in" in proc.stderr, proc.stderr
    assert not [ln for ln in proc.stderr.splitlines() if ln.endswith(": cached")], proc.stderr
    assert proc.stdout.strip() == library
    _intact(library, "cache_trunnion")


@pytest.mark.slow
@pytest.mark.parametrize("how", list(CORRUPTIONS))
def test_replay_rebuilds_a_changed_library_before_loading_it(cache, how, tmp_path):
    """replay (chaincompd's open_model) checks the digest before dlopen: the changed library is
    built again (chaincomp build, its progress on stderr) and the replay corrects the commands."""
    machine = cache["paths"]["cache_trunnion"][0]
    env = cache["env"]
    library = _built(env, machine)
    log, csv, cfg = tmp_path / "axes.lcmlog", tmp_path / "out.csv", tmp_path / "r.yaml"
    cfg.write_text(CONFIG_TEXT)
    proc = chaincomp(env, "simulate-log", machine, "-o", str(log), "--seconds", "0.2")
    assert proc.returncode == 0, proc.stderr
    other = _built(env, cache["paths"]["cache_other"][0])
    for each in glob.glob(os.path.join(os.path.dirname(os.path.dirname(library)), "cache_trunnion-*", "*.so")):
        CORRUPTIONS[how](each, other)   # every key's: replay's compiled-in key is the one it reads
    proc = chaincomp(env, "replay", machine, str(log), "--params", params_of(machine),
                     "--config", str(cfg), "--csv", str(csv))
    assert proc.returncode == 0, proc.stderr
    assert "building it again" in proc.stderr and "compiled in" in proc.stderr, proc.stderr
    _intact(library, "cache_trunnion")
    head = csv.read_text().splitlines()[0].split(",")
    data = np.genfromtxt(csv, delimiter=",", skip_header=1, dtype=float)
    cmd = data[:, [i for i, c in enumerate(head) if c.startswith("commanded_")]]
    cor = data[:, [i for i, c in enumerate(head) if c.startswith("corrected_")]]
    assert len(cmd) == 200 and np.max(np.abs(cor - cmd)) > 1e-4
