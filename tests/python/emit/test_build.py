"""Models built at run time (chaincomp build, design §10): a machine file the test writes into
its temporary folder (never under configs/), built into a shared library, loaded by chaincompd
and replay; a stale, foreign or wrong-ABI library is refused with one line, never used."""

import ctypes
import glob
import hashlib
import json
import os
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest

from helpers import ROOT, machine_path
from helpers import DAEMON, NETNS, PY, needs_netns

SOURCE = machine_path("trunnion_ac")
HEADER = os.path.join(ROOT, "runtime", "include", "chaincomp", "model_library.hpp")
E2E = os.path.join(ROOT, "tests", "e2e")
PARAMS_TEXT = """machine: {name}
values:
  EY0A: 12 um
  EZ0A: -8 um
  EB0A: 6 arcsec
  EC0A: -4 arcsec
  EA0A: 10 arcsec
  EX0C: 5 um
  EY0C: -7 um
  EA0C: 3 arcsec
  EB0C: -5 arcsec
  EC0C: 8 arcsec
"""
# replay with the full correction on every command (no ramp, generous limits)
CONFIG_TEXT = """lcm_url: "memq://"
ramp_time: 0.0
linear_axes: {max_step: 5.0, max_correction: 1.0, max_correction_step: 1.0}
rotary_axes: {max_step: 5.0, max_correction: 1.0, max_correction_step: 1.0}
"""


def fnv1a64(data: bytes) -> int:
    # the FNV-1a 64 definition (offset basis and prime of the FNV reference), written here
    h = 0xCBF29CE484222325
    for b in data:
        h = ((h ^ b) * 0x100000001B3) % 2**64
    return h


def variant(folder, name: str, h: int = 430, tool_length: int = 100) -> str:
    """trunnion_ac renamed, with its spindle height H (and tool length L) changed."""
    with open(SOURCE) as f:
        text = f.read()
    text = text.replace("name: trunnion_ac", f"name: {name}", 1)
    text = text.replace("nominal: 450,", f"nominal: {h},", 1).replace("nominal: 100,", f"nominal: {tool_length},", 1)
    path = os.path.join(folder, f"{name}.yaml")
    with open(path, "w") as f:
        f.write(text)
    with open(os.path.join(folder, f"{name}-params.yaml"), "w") as f:
        f.write(PARAMS_TEXT.format(name=name))
    return path


def params_of(machine: str) -> str:
    return machine[:-len(".yaml")] + "-params.yaml"


def chaincomp(env, *args):
    return subprocess.run([PY, "-m", "chaincomp.cli.main", *args], capture_output=True, text=True, env=env, cwd=ROOT)


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """A machine outside configs/ and its library, built by two concurrent `chaincomp build`s."""
    folder = tmp_path_factory.mktemp("machines")
    env = dict(os.environ, XDG_CACHE_HOME=str(tmp_path_factory.mktemp("cache")))
    machine = variant(folder, "test_trunnion")
    procs = [subprocess.Popen([PY, "-m", "chaincomp.cli.main", "build", machine], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True, env=env, cwd=ROOT) for _ in range(2)]
    outs = [p.communicate(timeout=600) for p in procs]
    return {"machine": machine, "env": env, "outs": outs, "rcs": [p.returncode for p in procs],
            "path": outs[0][0].strip(), "folder": str(folder)}


@pytest.mark.slow
def test_concurrent_builds_compile_once_and_agree(built):
    assert built["rcs"] == [0, 0], built["outs"]
    paths = {out.strip() for out, _ in built["outs"]}
    assert len(paths) == 1 and os.path.isfile(built["path"])
    assert sum("compiled in" in err for _, err in built["outs"]) == 1
    cache = os.path.join(built["env"]["XDG_CACHE_HOME"], "chaincomp")
    # the result appeared by one rename: no temporary folder is left behind
    assert [n for n in os.listdir(cache) if n.startswith(".")] == []
    assert built["path"].startswith(cache + "/test_trunnion-")


class _Layout(ctypes.Structure):
    _fields_ = [(n, ctypes.c_uint32) for n in ("entry", "info", "axis", "param", "varying", "varying_item")]


class _Library(ctypes.Structure):
    # model_library.hpp's ModelLibrary
    _fields_ = [("abi", ctypes.c_int), ("layout", _Layout), ("name", ctypes.c_char_p),
                ("source_hash", ctypes.c_uint64), ("source_text", ctypes.POINTER(ctypes.c_char)),
                ("source_size", ctypes.c_size_t), ("toolchain", ctypes.c_char_p), ("entry", ctypes.c_void_p)]


@pytest.mark.slow
def test_library_has_one_entry_point_with_name_hash_text_abi(built):
    lib = ctypes.CDLL(built["path"])
    lib.chaincomp_model_library.restype = ctypes.POINTER(_Library)
    got = lib.chaincomp_model_library().contents
    with open(built["machine"], "rb") as f:
        source = f.read()
    with open(HEADER) as f:
        abi = int(re.search(r"^constexpr int kModelAbi = (\d+);", f.read(), re.M).group(1))
    assert got.abi == abi
    assert got.name == b"test_trunnion"
    assert got.source_hash == fnv1a64(source)
    assert ctypes.string_at(got.source_text, got.source_size) == source
    compiler = subprocess.run(["c++", "--version"], capture_output=True, text=True).stdout.splitlines()[0]
    lines = got.toolchain.decode().split("\n")
    assert lines[:2] == [f"chaincomp model abi {abi}", compiler]
    assert lines[-1] == f"sources {sources_digest()}"
    assert got.entry
    nm = shutil.which("nm")
    if nm:
        syms = subprocess.run([nm, "-D", "--defined-only", built["path"]], capture_output=True, text=True).stdout
        assert [line.split()[-1] for line in syms.splitlines()] == ["chaincomp_model_library"]


def sources_digest() -> str:
    """What the key says the model's code comes from, computed here from its definition (the
    code generator's Python files and the runtime headers: SHA-256 of each, listed by path)."""
    files = sorted(glob.glob(os.path.join(ROOT, "codegen", "chaincomp", "**", "*.py"), recursive=True)
                   + glob.glob(os.path.join(ROOT, "runtime", "include", "chaincomp", "*.hpp")))
    text = "".join(f"{os.path.relpath(f, ROOT)} {hashlib.sha256(open(f, 'rb').read()).hexdigest()}\n" for f in files)
    return hashlib.sha256(text.encode()).hexdigest()


@pytest.mark.slow
def test_a_library_of_older_chaincomp_code_is_not_reused(built, tmp_path):
    # The same machine file and compiler, but another code generator or runtime headers (an
    # upgrade of chaincomp: here another digest in model_build.json): a new library, compiled.
    with open(os.path.join(ROOT, "build", "model_build.json")) as f:
        cfg = json.load(f)
    assert cfg["sources"] == sources_digest()  # the build's digest is the sources' (re-configured on change)
    cfg["sources"] = "0" * 64
    folder = tmp_path / "upgraded"
    folder.mkdir()
    (folder / "model_build.json").write_text(json.dumps(cfg))
    # (a cache of its own holding the built library: the other tests count solver objects)
    cache = tmp_path / "cache"
    shutil.copytree(built["env"]["XDG_CACHE_HOME"], cache)
    env = dict(built["env"], CHAINCOMP_BUILD_DIR=str(folder), XDG_CACHE_HOME=str(cache))
    proc = chaincomp(env, "build", built["machine"])
    assert proc.returncode == 0, proc.stderr
    assert "compiled in" in proc.stderr
    path = proc.stdout.strip()
    old = built["path"].replace(built["env"]["XDG_CACHE_HOME"], str(cache))
    assert os.path.dirname(path) != os.path.dirname(old) and os.path.isfile(old)
    lib = ctypes.CDLL(path)
    lib.chaincomp_model_library.restype = ctypes.POINTER(_Library)
    assert lib.chaincomp_model_library().contents.toolchain.decode().endswith("\nsources " + "0" * 64)
    # and a model_build.json from before the digest names the fix
    del cfg["sources"]
    (folder / "model_build.json").write_text(json.dumps(cfg))
    proc = chaincomp(env, "build", built["machine"])
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert proc.stderr.splitlines()[-1].endswith("is from an older chaincomp: re-configure the C++ build (tools/setup)")


@pytest.mark.slow
def test_cached_build_is_reused_and_copied(built, tmp_path):
    before = os.stat(built["path"]).st_mtime_ns
    proc = chaincomp(built["env"], "build", built["machine"], "-o", str(tmp_path / "out"))
    assert proc.returncode == 0, proc.stderr
    assert "cached" in proc.stderr and "compiled in" not in proc.stderr
    assert os.stat(built["path"]).st_mtime_ns == before
    copy = proc.stdout.strip()
    assert copy == str(tmp_path / "out" / "test_trunnion.so")
    with open(copy, "rb") as a, open(built["path"], "rb") as b:
        assert a.read() == b.read()
    # with its digest, which coreutils' sha256sum -c accepts and --model checks before loading
    assert sorted(os.listdir(tmp_path / "out")) == ["test_trunnion.so", "test_trunnion.so.sha256"]
    assert subprocess.run(["sha256sum", "-c", "--status", "test_trunnion.so.sha256"], cwd=tmp_path / "out").returncode == 0


@pytest.mark.slow
def test_a_model_library_given_directly_is_checked_against_its_digest(built, tmp_path):
    """chaincompd --model LIB.so (and replay's): a copy made by build -o loads; without its
    .sha256 or changed since, it is refused before dlopen, and the refusal's advice works."""
    out = tmp_path / "out"
    assert chaincomp(built["env"], "build", built["machine"], "-o", str(out)).returncode == 0
    lib = str(out / "test_trunnion.so")
    args = ("--machine", built["machine"], "--params", params_of(built["machine"]), "--model", lib)
    log = tmp_path / "axes.lcmlog"
    assert chaincomp(built["env"], "simulate-log", built["machine"], "-o", str(log), "--seconds", "0.01").returncode == 0
    replay = [os.path.join(ROOT, "build", "bin", "chaincomp_replay"), *args, "--in", str(log), "--quiet"]
    assert subprocess.run(replay, capture_output=True, env=built["env"], timeout=60).returncode == 0

    os.remove(lib + ".sha256")
    proc = daemon(built["env"], *args)
    assert proc.returncode == 2
    advice = f"(cd {out} && sha256sum test_trunnion.so > test_trunnion.so.sha256)"
    assert proc.stderr == (f"chaincompd: error: --model: {lib}: no test_trunnion.so.sha256 beside it, the digest "
                           "chaincomp build records (build -o DIR copies both): copy the two together, or for a "
                           f"library you built and trust record it with {advice}\n")
    subprocess.run(advice, shell=True, check=True)
    assert subprocess.run(replay, capture_output=True, env=built["env"], timeout=60).returncode == 0

    with open(lib, "r+b") as f:   # truncated, as a full disk leaves a copy: it crashed the start (SIGBUS)
        f.truncate(os.path.getsize(lib) // 2)
    for program in (daemon(built["env"], *args),
                    subprocess.run(replay, capture_output=True, text=True, env=built["env"], timeout=60)):
        assert program.returncode == 2, program.stderr
        assert program.stderr.strip().splitlines()[-1].endswith(
            f"--model: {lib}: not the library recorded in test_trunnion.so.sha256 (its SHA-256 differs: truncated or "
            f"overwritten since it was built): copy it again with its .sha256, or rebuild it with chaincomp build "
            f"{built['machine']} -o {out}")
    assert chaincomp(built["env"], "build", built["machine"], "-o", str(out)).returncode == 0   # the advice
    assert subprocess.run(replay, capture_output=True, env=built["env"], timeout=60).returncode == 0


@pytest.mark.slow
def test_no_compiler_names_the_debian_package(built, tmp_path):
    with open(os.path.join(ROOT, "build", "model_build.json")) as f:
        cfg = json.load(f)
    cfg["compiler"] = "/nonexistent/usr/bin/c++"
    (tmp_path / "model_build.json").write_text(json.dumps(cfg))
    env = dict(built["env"], CHAINCOMP_BUILD_DIR=str(tmp_path), XDG_CACHE_HOME=str(tmp_path / "cache"))
    proc = chaincomp(env, "build", built["machine"])
    assert proc.returncode == 2
    assert proc.stderr.splitlines() == [
        "chaincomp build: error: no C++ compiler (/nonexistent/usr/bin/c++ is missing): "
        "install the Debian package g++ (apt-get install g++)"]
    assert not (tmp_path / "cache").exists()


@pytest.mark.slow
def test_bad_machine_file_is_one_line(built, tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: bad\nsymbols: 3\n")
    proc = chaincomp(built["env"], "build", str(bad))
    assert proc.returncode == 2 and len(proc.stderr.splitlines()) == 1
    assert proc.stderr.startswith(f"chaincomp build: error: {bad}")


def daemon(env, *args):
    return subprocess.run([DAEMON, *args], capture_output=True, text=True, timeout=60, env=env)


def recorded(path: str) -> str:
    """PATH with PATH.sha256 beside it, written by coreutils' sha256sum as the refusal of a
    library without one advises (--model checks it before loading)."""
    folder, name = os.path.split(path)
    subprocess.run(f"sha256sum {name} > {name}.sha256", shell=True, cwd=folder, check=True)
    return path


def test_library_of_another_machine_is_refused(built, tmp_path):
    (tmp_path / "r.yaml").write_text(CONFIG_TEXT)
    proc = daemon(built["env"], "--machine", machine_path("five_axis_ac"), "--params",
                  os.path.join(ROOT, "configs", "params", "five_axis_ac-demo.yaml"), "--config",
                  str(tmp_path / "r.yaml"), "--model", built["path"])
    assert proc.returncode == 2
    assert proc.stderr == (f"chaincompd: error: --model: {built['path']}: the model of machine 'test_trunnion', "
                           f"not of 'five_axis_ac' ({machine_path('five_axis_ac')})\n")


def _fake_library(tmp_path, abi_expr: str) -> str:
    """A library with the entry point and a chosen ABI number, compiled here."""
    src = tmp_path / "fake.cpp"
    src.write_text('#include "chaincomp/model_library.hpp"\n'
                   f"static const chaincomp::ModelLibrary lib = {{{abi_expr}, chaincomp::kModelLayout, \"x\", 0, "
                   "\"\", 0, \"\", nullptr};\n"
                   'extern "C" const chaincomp::ModelLibrary* chaincomp_model_library() noexcept { return &lib; }\n')
    out = str(tmp_path / "fake.so")
    subprocess.run(["c++", "-std=c++17", "-shared", "-fPIC", "-I", os.path.join(ROOT, "runtime", "include"),
                    "-isystem", "/usr/include/eigen3", str(src), "-o", out], check=True)
    return recorded(out)


@pytest.mark.slow
def test_library_of_another_abi_is_refused(built, tmp_path):
    fake = _fake_library(tmp_path, "chaincomp::kModelAbi + 1")
    with open(HEADER) as f:
        abi = int(re.search(r"^constexpr int kModelAbi = (\d+);", f.read(), re.M).group(1))
    proc = daemon(built["env"], "--machine", built["machine"], "--params", params_of(built["machine"]),
                  "--model", fake)
    assert proc.returncode == 2
    assert proc.stderr == (f"chaincompd: error: --model: {fake}: model ABI {abi + 1}, this program reads ABI {abi}: "
                           f"rebuild it with chaincomp build {built['machine']}\n")


def test_a_library_without_the_entry_point_is_refused(built, tmp_path):
    other = str(tmp_path / "libchaincomp_alloc_counter.so")
    shutil.copy(os.path.join(ROOT, "build", "runtime", "libchaincomp_alloc_counter.so"), other)
    recorded(other)
    proc = daemon(built["env"], "--machine", built["machine"], "--params", params_of(built["machine"]),
                  "--model", other)
    assert proc.returncode == 2
    assert proc.stderr.endswith(f"{other}: not a chaincomp model library (no chaincomp_model_library)\n")


def _replay_exact(built, machine, tmp_path, extra=()):
    """replay of a simulated log on `machine`; largest tool point error (mm) of the corrected
    axes against the exact model's nominal pose at the commands."""
    sys.path.insert(0, E2E)
    from common import exact_check  # the e2e scenarios' check: chaincomp.symbolic.numeric.ExactModel
    log, csv, cfg = tmp_path / "axes.lcmlog", tmp_path / "out.csv", tmp_path / "r.yaml"
    cfg.write_text(CONFIG_TEXT)
    proc = chaincomp(built["env"], "simulate-log", machine, "-o", str(log), "--seconds", "0.5")
    assert proc.returncode == 0, proc.stderr
    proc = chaincomp(built["env"], "replay", machine, str(log), "--params", params_of(machine),
                     "--config", str(cfg), "--csv", str(csv), *extra)
    assert proc.returncode == 0, proc.stderr
    head = csv.read_text().splitlines()[0].split(",")
    data = np.genfromtxt(csv, delimiter=",", skip_header=1, dtype=float)
    cmd = data[:, [i for i, c in enumerate(head) if c.startswith("commanded_")]]
    cor = data[:, [i for i, c in enumerate(head) if c.startswith("corrected_")]]
    assert len(cmd) == 500 and np.max(np.abs(cor - cmd)) > 1e-4
    return exact_check(cmd, cor, machine, params_of(machine))[0], proc.stderr


@pytest.mark.slow
def test_replay_on_a_built_machine(built, tmp_path):
    dp, err = _replay_exact(built, built["machine"], tmp_path)
    assert "chaincomp build:" not in err  # the cached library
    assert dp < 1e-6


def _scenario(env, *args):
    proc = subprocess.run([NETNS, PY, os.path.join(E2E, "e2e_built.py"), *args], capture_output=True, text=True,
                          cwd=ROOT, env=env, timeout=600)
    print(proc.stdout, proc.stderr)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout


@pytest.mark.slow
@needs_netns
def test_daemon_on_a_built_machine_then_a_changed_constant(built, tmp_path):
    env = built["env"]
    machine = str(tmp_path / "test_trunnion.yaml")  # a copy: the same content, the same cached library
    shutil.copy(built["machine"], machine)
    shutil.copy(params_of(built["machine"]), params_of(machine))
    out = _scenario(env, machine, params_of(machine), "1000")
    assert "chaincomp build:" not in out  # the library chaincomp build left in the cache
    assert "max point error" in out and "heap allocations after warm-up 0" in out
    old = str(tmp_path / "old.so")
    shutil.copy(built["path"], old)
    recorded(old)

    # one constant changes: the tool length L, 100 -> 120 mm
    with open(machine) as f:
        text = f.read()
    with open(machine, "w") as f:
        f.write(text.replace("nominal: 100,", "nominal: 120,", 1))
    with open(machine, "rb") as f:
        new_hash = fnv1a64(f.read())
    proc = daemon(env, "--machine", machine, "--params", params_of(machine), "--model", old)
    assert proc.returncode == 2
    old_hash = fnv1a64(text.encode())
    assert proc.stderr == (f"chaincompd: error: --model: {old}: built from another version of {machine} (hash "
                           f"{old_hash:016x}, the file's is {new_hash:016x}): rebuild it with chaincomp build "
                           f"{machine}\n")

    # a stale library where the new one belongs in the cache is refused, not used (with its
    # digest: intact, so loaded and refused as built from another version)
    new_path = built["path"].replace(f"-{old_hash:016x}-", f"-{new_hash:016x}-")
    os.makedirs(os.path.dirname(new_path))
    shutil.copy(old, new_path)
    shutil.copy(built["path"] + ".sha256", new_path + ".sha256")
    proc = daemon(env, "--machine", machine, "--params", params_of(machine))
    assert proc.returncode == 2 and proc.stderr.startswith(f"chaincompd: error: {new_path}: built from another version")
    shutil.rmtree(os.path.dirname(new_path))

    # without the stale one the daemon builds the new model itself, and its targets follow the new L
    out = _scenario(env, machine, params_of(machine), "300")
    assert "chaincomp build: test_trunnion: compiled in" in out
    assert "max point error" in out
    assert os.path.isfile(new_path)


@pytest.mark.slow
def test_the_solver_is_compiled_once_per_machine_shape(built):
    """The compensation solver depends on the machine's shape alone: the first build compiled
    it (trunnion_ac: 5 axes, the last two rotary (kind mask 0b11000 = 24), tool point and
    direction, so 6 residual rows),
    a second machine of that shape (another spindle height) links the cached object."""
    assert sum("compiling the compensation solver" in err for _, err in built["outs"]) == 1
    cache = os.path.join(built["env"]["XDG_CACHE_HOME"], "chaincomp")
    objects = [os.path.join(cache, d, n) for d in os.listdir(cache) if d.startswith("solvers-")
               for n in os.listdir(os.path.join(cache, d)) if n.endswith(".o")]
    assert [os.path.basename(o) for o in objects] == ["core_5_24_6_6_0.o"]
    other = variant(built["folder"], "test_trunnion_h", h=460)
    proc = chaincomp(built["env"], "build", other)
    assert proc.returncode == 0, proc.stderr
    assert "compiled in" in proc.stderr and "compensation solver" not in proc.stderr
    symbols = subprocess.run(["nm", "-C", proc.stdout.strip()], capture_output=True, text=True).stdout
    assert "chaincomp::Core<5, 24u, 6, 6, false>::solve" in symbols
    defined = subprocess.run(["nm", "-C", "--defined-only", objects[0]], capture_output=True, text=True).stdout
    assert "chaincomp::Core<5, 24u, 6, 6, false>::compensate" in defined


@pytest.mark.slow
def test_build_output_folder_is_checked_before_the_build(tmp_path):
    """-o creates at most the folder itself, never missing parents, and says so before compiling."""
    proc = subprocess.run([sys.executable, "-m", "chaincomp.cli.main", "build", os.path.join(ROOT, "configs",
                           "machines", "angle_head.yaml"), "-o", str(tmp_path / "missing" / "x")],
                          capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert proc.returncode == 2 and f"folder {tmp_path / 'missing'} does not exist" in proc.stderr, proc.stderr
    assert not (tmp_path / "missing").exists()
    (tmp_path / "f").write_text("")
    proc = subprocess.run([sys.executable, "-m", "chaincomp.cli.main", "build", os.path.join(ROOT, "configs",
                           "machines", "angle_head.yaml"), "-o", str(tmp_path / "f")],
                          capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert proc.returncode == 2 and "is a file, expected a folder" in proc.stderr, proc.stderr


# --- chaincomp build --linuxcnc: the realtime HAL component chaincomp_rt ------------------

FIVE = os.path.join(ROOT, "configs", "machines", "five_axis_ac.yaml")
DEMO = os.path.join(ROOT, "configs", "params", "five_axis_ac-demo.yaml")


@pytest.mark.slow
def test_linuxcnc_options_are_checked_before_any_work(tmp_path):
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path)}
    proc = chaincomp(env, "build", FIVE, "--params", DEMO)
    assert proc.returncode == 2 and "--params goes with --linuxcnc" in proc.stderr, proc.stderr
    proc = chaincomp(env, "build", FIVE, "--install")
    assert proc.returncode == 2 and "--install goes with --linuxcnc" in proc.stderr, proc.stderr
    proc = chaincomp(env, "build", FIVE, "--name", "cc")
    assert proc.returncode == 2 and "--name goes with --linuxcnc" in proc.stderr, proc.stderr
    for bad in ("Chaincomp", "1cc", "cc-rt", "a" * 41, "cc rt", ""):
        proc = chaincomp(env, "build", "--linuxcnc", FIVE, "--name", bad)
        assert proc.returncode == 2 and "--name" in proc.stderr and "Traceback" not in proc.stderr, (bad, proc.stderr)
    # tables and polynomials: not in the realtime component (yet), refused naming the file and error
    laser = os.path.join(ROOT, "configs", "params", "five_axis_ac-laser.yaml")
    proc = chaincomp(env, "build", "--linuxcnc", FIVE, "--params", laser)
    assert proc.returncode == 2, proc.stderr
    assert "five_axis_ac-laser.yaml: EXX is a table or polynomial" in proc.stderr
    assert "Traceback" not in proc.stderr and not os.listdir(tmp_path)
    bad = tmp_path / "bad.yaml"
    bad.write_text("machine: five_axis_ac\nvalues:\n  EXX: 4 parsecs\n")
    proc = chaincomp(env, "build", "--linuxcnc", FIVE, "--params", str(bad))
    assert proc.returncode == 2 and "bad.yaml:3" in proc.stderr and "Traceback" not in proc.stderr, proc.stderr


def test_linuxcnc_header_bakes_the_params_in_internal_units():
    from chaincomp.emit.build import rt_model_header
    from chaincomp.model.machine import load_machine

    m = load_machine(FIVE)
    text = rt_model_header(m, {"EXX": 0.004, "G": 151.0}, "p.yaml")
    values = re.findall(r"^    (\S+),  // (\w+)$", text, re.M)
    got = {name: float(v) for v, name in values}
    assert got["EXX"] == 0.004 and got["G"] == 151.0       # given
    assert got["Yp"] == pytest.approx(50 * 3.141592653589793 / 180, rel=1e-15)  # a constant at its nominal, in rad
    assert got["EYX"] == 0.0                                 # an error not given
    # one value per constant and error, in the machine file's order (kParams)
    assert [n for _, n in values] == [s.name for s in m.symbols if s.role != "axis"]
    # chaincompd's default limits, the machine file's travel
    assert "{-400.0, 400.0, 10.0, 0.5, 0.001},  // X [mm]" in text
    assert "{-95.0, 95.0, 5.0, 0.5, 0.001},  // Ap [deg]" in text


@pytest.mark.skipif(not os.path.exists("/usr/share/linuxcnc/Makefile.modinc"),
                    reason="LinuxCNC's development files are not installed (tools/setup-linuxcnc)")
def test_linuxcnc_module_exports_only_the_rtapi_entry_points(tmp_path):
    proc = chaincomp(dict(os.environ), "build", "--linuxcnc", FIVE, "--params", DEMO,
                     "-o", str(tmp_path / "out"))
    assert proc.returncode == 0, proc.stderr
    path = proc.stdout.split()[0]
    assert path == str(tmp_path / "out" / "chaincomp_rt.so")
    syms = subprocess.run(["nm", "-D", "--defined-only", path], capture_output=True, text=True).stdout.split()
    assert {"rtapi_app_main", "rtapi_app_exit"} <= set(syms)
    assert not [s for s in syms if s.startswith("_Z")]  # no C++ symbol leaks into rtapi_app
    needed = subprocess.run(["objdump", "-p", path], capture_output=True, text=True).stdout
    assert "NEEDED               libstdc++.so.6" in needed
