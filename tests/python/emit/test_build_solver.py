"""chaincomp build's compensation solver, compiled once per machine shape (build.py's
_solver_object) and linked into each model: a failed or killed compile, a second build
waiting for the first, the key over the runtime headers, a solver folder deleted by hand,
two models of one shape in one process, and a generated model compiled alone without
CHAINCOMP_PREBUILT_CORE."""

import ctypes
import json
import os
import shutil
import signal
import subprocess
import time

import numpy as np
import pytest

from helpers import ROOT
from test_build import PY, chaincomp, variant

CONFIG = os.path.join(ROOT, "build", "model_build.json")


def toolchain_dir(tmp_path, compiler=None, include=None):
    """A build folder whose model_build.json names another compiler or include folder."""
    with open(CONFIG) as f:
        cfg = json.load(f)
    if compiler is not None:
        cfg["compiler"] = compiler
    if include is not None:
        cfg["include_dirs"] = [include if d.endswith(os.path.join("runtime", "include")) else d
                               for d in cfg["include_dirs"]]
    folder = tmp_path / "buildcfg"
    folder.mkdir(exist_ok=True)
    (folder / "model_build.json").write_text(json.dumps(cfg))
    return str(folder)


def wrapper(tmp_path, on_solver: str) -> str:
    """A compiler that runs `on_solver` (sh; $out: the -o target) for the solver's source
    and is the real compiler otherwise."""
    with open(CONFIG) as f:
        real = json.load(f)["compiler"]
    path = tmp_path / "cxx"
    path.write_text("\n".join([
        "#!/bin/sh",
        'out=""; solver=""; prev=""',
        'for a in "$@"; do',
        '  [ "$prev" = "-o" ] && out="$a"',
        '  case "$a" in *core_*.cpp) solver=1;; esac',
        '  prev="$a"',
        "done",
        'if [ -n "$solver" ]; then',
        on_solver,
        "fi",
        f'exec {real} "$@"', ""]))
    path.chmod(0o755)
    return str(path)


def env_for(tmp_path, build_dir):
    return dict(os.environ, CHAINCOMP_BUILD_DIR=build_dir, XDG_CACHE_HOME=str(tmp_path / "cache"))


def cache_entries(tmp_path):
    root = tmp_path / "cache" / "chaincomp"
    return sorted(str(p.relative_to(root)) for p in root.rglob("*")) if root.exists() else []


def failed_solver_build(tmp_path, on_solver: str, name: str):
    """`chaincomp build` of a machine whose solver compile runs `on_solver` and fails: its
    stderr, after checking it ends on the one line naming the compiler and the solver."""
    cxx = wrapper(tmp_path, on_solver)
    env = env_for(tmp_path, toolchain_dir(tmp_path, compiler=cxx))
    proc = chaincomp(env, "build", variant(str(tmp_path), name))
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.splitlines()[-1].startswith(f"chaincomp build: error: {cxx} failed on the compensation solver (")
    return proc.stderr


@pytest.mark.slow
def test_a_failed_solver_compile_names_the_first_error_and_leaves_no_half_object(tmp_path):
    # the compiler writes half an object, then fails (as one that runs out of memory late)
    err = failed_solver_build(tmp_path, 'echo half > "$out"; echo "x.cpp: In function:" >&2; '
                                        'echo "x.cpp:3:1: error: boom" >&2; exit 1', "solver_fail")
    assert err.splitlines()[-1].endswith("): x.cpp:3:1: error: boom")
    assert "Traceback" not in err
    left = cache_entries(tmp_path)
    assert not any(e.endswith((".o", ".tmp", ".so")) for e in left), left
    assert not any(os.path.basename(e).startswith(".") for e in left), left  # no temporary model folder


@pytest.mark.slow
def test_a_killed_solver_compile_says_so(tmp_path):
    err = failed_solver_build(tmp_path, 'echo half > "$out"; kill -9 $$', "solver_killed")
    assert err.splitlines()[-1].endswith(".cpp): killed by signal 9, no message")
    assert not any(e.endswith((".o", ".tmp", ".so")) for e in cache_entries(tmp_path))


@pytest.mark.slow
def test_two_machines_of_one_shape_built_at_once_compile_the_solver_once(tmp_path):
    # the solver's compile is slowed, so that the second build arrives while it runs
    cxx = wrapper(tmp_path, "sleep 4")
    env = env_for(tmp_path, toolchain_dir(tmp_path, compiler=cxx))
    machines = [variant(str(tmp_path), "shape_a"), variant(str(tmp_path), "shape_b", h=470)]
    procs = [subprocess.Popen([PY, "-m", "chaincomp.cli.main", "build", m], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True, env=env, cwd=ROOT) for m in machines]
    outs = [p.communicate(timeout=600) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], outs
    errs = [err for _, err in outs]
    assert sum("compiling the compensation solver" in e for e in errs) == 1
    assert sum("another build is making the compensation solver of this shape; waiting for it" in e
               for e in errs) == 1
    objects = [e for e in cache_entries(tmp_path) if e.endswith(".o")]
    assert len(objects) == 1 and objects[0].endswith("/core_5_24_6_6_0.o")
    # both libraries work: each loads and corrects (checked against its own forward model)
    for out, _ in outs:
        assert_compensates(load(out.strip()))


@pytest.mark.slow
def test_the_solver_key_covers_the_headers_and_skips_what_is_no_header(tmp_path):
    include = tmp_path / "include"
    shutil.copytree(os.path.join(ROOT, "runtime", "include"), include)
    (include / "chaincomp" / "old").mkdir()  # a folder among the headers
    (include / "chaincomp" / "compensate.hpp~").write_text("an editor's backup")
    env = env_for(tmp_path, toolchain_dir(tmp_path, include=str(include)))
    proc = chaincomp(env, "build", variant(str(tmp_path), "key_a"))
    assert proc.returncode == 0, proc.stderr
    first = [e for e in cache_entries(tmp_path) if e.endswith(".o")]
    # the backup changed: the same solver; a header changed: another one
    (include / "chaincomp" / "compensate.hpp~").write_text("another backup")
    proc = chaincomp(env, "build", variant(str(tmp_path), "key_b", h=440))
    assert proc.returncode == 0 and "compensation solver" not in proc.stderr, proc.stderr
    with open(include / "chaincomp" / "varying.hpp", "a") as f:
        f.write("\n// changed\n")
    proc = chaincomp(env, "build", variant(str(tmp_path), "key_c", h=445))
    assert proc.returncode == 0 and "compiling the compensation solver" in proc.stderr, proc.stderr
    second = [e for e in cache_entries(tmp_path) if e.endswith(".o")]
    assert len(second) == 2 and first[0] in second
    assert first[0].split("/")[0] != next(e for e in second if e != first[0]).split("/")[0]


@pytest.mark.slow
def test_no_runtime_headers_is_one_line(tmp_path):
    env = env_for(tmp_path, toolchain_dir(tmp_path, include=str(tmp_path / "nowhere" / "runtime" / "include")))
    proc = chaincomp(env, "build", variant(str(tmp_path), "no_headers"))
    assert proc.returncode == 2
    lines = proc.stderr.splitlines()
    assert lines[-1].startswith("chaincomp build: error: no chaincomp/compensate.hpp under the include folders of ")
    assert "Traceback" not in proc.stderr


@pytest.mark.slow
def test_a_solver_folder_deleted_by_hand_is_compiled_again(tmp_path):
    env = env_for(tmp_path, toolchain_dir(tmp_path))
    assert chaincomp(env, "build", variant(str(tmp_path), "gone_a")).returncode == 0
    root = tmp_path / "cache" / "chaincomp"
    for d in root.glob("solvers-*"):
        shutil.rmtree(d)
    proc = chaincomp(env, "build", variant(str(tmp_path), "gone_b", h=455))
    assert proc.returncode == 0, proc.stderr
    assert "compiling the compensation solver" in proc.stderr
    assert_compensates(load(proc.stdout.strip()))


# --- the libraries through their entry point (model_library.hpp, model_info.hpp) ---------

class _ParamInfo(ctypes.Structure):
    _fields_ = [("name", ctypes.c_char_p), ("role", ctypes.c_int), ("unit", ctypes.c_char_p),
                ("kind", ctypes.c_int), ("to_internal", ctypes.c_double), ("nominal", ctypes.c_double)]


class _MachineInfo(ctypes.Structure):
    _fields_ = [("name", ctypes.c_char_p), ("source_hash", ctypes.c_uint64), ("source_file", ctypes.c_char_p),
                ("num_axes", ctypes.c_int), ("axes", ctypes.c_void_p), ("num_params", ctypes.c_int),
                ("params", ctypes.POINTER(_ParamInfo)), ("pose_size", ctypes.c_int),
                ("corrects_direction", ctypes.c_bool), ("corrects_orientation", ctypes.c_bool)]


_P = ctypes.POINTER(ctypes.c_double)
_V = ctypes.c_void_p


class _Entry(ctypes.Structure):
    _fields_ = [("info", ctypes.POINTER(_MachineInfo)), ("model_size", ctypes.c_size_t),
                ("model_align", ctypes.c_size_t),
                ("prepare", ctypes.CFUNCTYPE(None, _P, _V)),
                ("pose_exact", ctypes.CFUNCTYPE(None, _V, _P, _P)),
                ("pose_nominal", ctypes.CFUNCTYPE(None, _V, _P, _P)),
                ("pose_jacobian", _V), ("error", _V), ("max_order", ctypes.c_int),
                ("compensate", ctypes.CFUNCTYPE(ctypes.c_int, _V, _V, _P, ctypes.c_double, _P, _P, _P)),
                ("workspace_size", ctypes.c_size_t), ("workspace_align", ctypes.c_size_t),
                ("init_workspace", ctypes.CFUNCTYPE(None, _V)), ("num_errors", ctypes.c_int),
                ("attach_varying", _V), ("pose_jacobian_gain", _V)]


class _Library(ctypes.Structure):
    _fields_ = [("abi", ctypes.c_int), ("layout", ctypes.c_uint32 * 6), ("name", ctypes.c_char_p),
                ("source_hash", ctypes.c_uint64), ("source_text", _V), ("source_size", ctypes.c_size_t),
                ("toolchain", ctypes.c_char_p), ("entry", ctypes.POINTER(_Entry))]


# errors of micrometres and arcseconds (internal units: mm, rad) by name
ERRORS = {"EY0A": 0.012, "EZ0A": -0.008, "EB0A": 6 / 206264.8, "EC0A": -4 / 206264.8, "EA0A": 10 / 206264.8,
          "EX0C": 0.005, "EY0C": -0.007, "EA0C": 3 / 206264.8, "EB0C": -5 / 206264.8, "EC0C": 8 / 206264.8}
COMMANDS = [np.array([10.0 + k, 20.0, -30.0 + 0.5 * k, 0.3 + 0.001 * k, 0.5 - 0.002 * k]) for k in range(20)]


class Loaded:
    """A built library, prepared with ``values`` (internal units, by name; default ERRORS times
    ``scale``) and every other parameter at its nominal value."""
    def __init__(self, path, scale=1.0, values=None):
        values_by_name = {k: scale * v for k, v in ERRORS.items()} if values is None else values
        self.lib = ctypes.CDLL(path)  # RTLD_LOCAL, as open_model.cpp's dlopen
        fn = self.lib.chaincomp_model_library
        fn.restype = ctypes.POINTER(_Library)
        self.entry = fn().contents.entry.contents
        info = self.entry.info.contents
        self.n, self.pose_size = info.num_axes, info.pose_size
        params = [info.params[i] for i in range(info.num_params)]
        self.params = params
        self.model = ctypes.create_string_buffer(self.entry.model_size + self.entry.model_align)
        self.model_ptr = _align(self.model, self.entry.model_align)
        self.ws = ctypes.create_string_buffer(self.entry.workspace_size + self.entry.workspace_align)
        self.ws_ptr = _align(self.ws, self.entry.workspace_align)
        self.prepare(values_by_name)

    def prepare(self, values_by_name):
        """The model with these values (internal units, by name), the others nominal, and a fresh
        workspace."""
        values = np.array([values_by_name.get(p.name.decode(), p.nominal) for p in self.params])
        self.entry.prepare(values.ctypes.data_as(_P), self.model_ptr)
        self.entry.init_workspace(self.ws_ptr)

    def compensate(self, command, residual=None, weight=100.0, before=None):
        """(status, corrected); the residual (point, direction) into ``residual`` and the
        command's own into ``before`` where given; ``weight`` the objective's direction weight (mm)."""
        q = np.ascontiguousarray(command, dtype=float)
        out, res = np.zeros(self.n), np.zeros(2) if residual is None else residual
        s = self.entry.compensate(self.model_ptr, self.ws_ptr, q.ctypes.data_as(_P), weight, out.ctypes.data_as(_P),
                                  res.ctypes.data_as(_P), None if before is None else before.ctypes.data_as(_P))
        return s, out

    def pose(self, fn, q):
        q = np.ascontiguousarray(q, dtype=float)
        out = np.zeros(self.pose_size)
        fn(self.model_ptr, q.ctypes.data_as(_P), out.ctypes.data_as(_P))
        return out


def _align(buf, align):
    address = ctypes.addressof(buf)
    return address + (-address) % align


def load(path, scale=1.0):
    return Loaded(path, scale)


def assert_compensates(m, commands=COMMANDS):
    """Every command corrected (status ok), the actual pose at the correction equal to the
    nominal one at the command (point within 1e-7 mm, direction 1e-9); returns the corrections."""
    result = []
    for c in commands:
        s, q = m.compensate(c)
        assert s == 0
        actual, nominal = m.pose(m.entry.pose_exact, q), m.pose(m.entry.pose_nominal, c)
        assert np.linalg.norm(actual[:3] - nominal[:3]) <= 1e-7
        assert np.linalg.norm(actual[3:6] - nominal[3:6]) <= 1e-9
        assert np.max(np.abs(q - c)) > 1e-4  # a correction of the errors' size was made
        result.append(q)
    return np.array(result)


ALONE = """
import sys
sys.path[:0] = [{tests!r}, {here!r}]
from test_build_solver import load, COMMANDS
m = load({path!r}, {scale!r})
print(repr([[float(x) for x in m.compensate(c)[1]] for c in COMMANDS]))
"""


@pytest.mark.slow
def test_two_libraries_of_one_shape_in_one_process(tmp_path):
    """Each library keeps its own copy of the solver (hidden: only the entry point is
    exported, so neither binds to the other's); in one process both correct with their own
    geometry, bit for bit as each alone in a process of its own."""
    env = env_for(tmp_path, toolchain_dir(tmp_path))
    paths = []
    for name, h in (("one_a", 430), ("one_b", 480)):
        proc = chaincomp(env, "build", variant(str(tmp_path), name, h=h))
        assert proc.returncode == 0, proc.stderr
        paths.append(proc.stdout.strip())
    for path in paths:
        exported = subprocess.run(["nm", "-D", "--defined-only", path], capture_output=True, text=True,
                                  check=True).stdout.splitlines()
        assert [line.split()[-1] for line in exported] == ["chaincomp_model_library"]
    a, b = load(paths[0]), load(paths[1], scale=2.0)  # b: twice the errors
    # interleaved on one stream each (warm starts), the two models' corrections
    qa, qb = [], []
    for c in COMMANDS:
        for m, out in ((a, qa), (b, qb)):
            out.append(assert_compensates(m, [c])[0])
    qa, qb = np.array(qa), np.array(qb)
    assert np.max(np.abs(qa - qb)) > 1e-3  # each with its own model
    for path, q, scale in zip(paths, (qa, qb), (1.0, 2.0)):
        proc = subprocess.run([PY, "-c", ALONE.format(tests=os.path.dirname(os.path.dirname(os.path.abspath(__file__))), here=os.path.dirname(os.path.abspath(__file__)), path=path, scale=scale)],
                              capture_output=True, text=True, check=True)
        assert np.array_equal(np.array(eval(proc.stdout)), q)


MAIN = """
#include <cstdio>
#include "{a}.hpp"
#include "{b}.hpp"

template <class Axes, class F>
int run(const char* name, F compensate_one) {{
  Axes c;
  c << 10, 20, -30, 0.3, 0.5;
  double worst = 0;
  const int s = compensate_one(c, worst);
  std::printf("%s %d %.3e\\n", name, s, worst);
  return s;
}}

#define MODEL(NS)                                                                       \\
  [](const chaincomp::models::NS::Axes& c, double& worst) {{                             \\
    namespace M = chaincomp::models::NS;                                                \\
    M::Params p;                                                                        \\
    p.EY0A = 0.012; p.EB0A = 6 / 206264.8; p.EC0C = 8 / 206264.8;                       \\
    M::Model m;                                                                         \\
    M::prepare(p, m);                                                                   \\
    static M::Workspace ws;                                                             \\
    M::Result r;                                                                        \\
    const int s = static_cast<int>(M::compensate(m, ws, c, r));                         \\
    M::Pose actual, nominal;                                                            \\
    M::pose_exact(m, r.corrected, actual);                                              \\
    M::pose_nominal(m, c, nominal);                                                     \\
    worst = (actual - nominal).cwiseAbs().maxCoeff();                                   \\
    return s;                                                                           \\
  }}

int main() {{
  return run<chaincomp::models::{a}::Axes>("{a}", MODEL({a})) + run<chaincomp::models::{b}::Axes>("{b}", MODEL({b}));
}}
"""


@pytest.mark.slow
def test_generated_models_compile_alone_without_the_macro(tmp_path):
    """A user's program of two generated models of one shape, compiled without
    CHAINCOMP_PREBUILT_CORE: each NAME.cpp carries the solver; nothing else is linked."""
    machines = [variant(str(tmp_path), "alone_a"), variant(str(tmp_path), "alone_b", h=470)]
    out = tmp_path / "gen"
    proc = chaincomp(dict(os.environ), "generate", "-o", str(out), *machines)
    assert proc.returncode == 0, proc.stderr
    (out / "main.cpp").write_text(MAIN.format(a="alone_a", b="alone_b"))
    with open(CONFIG) as f:
        cfg = json.load(f)
    cmd = [cfg["compiler"], "-O0", "-std=c++17", *(f"-I{d}" for d in cfg["include_dirs"]), "main.cpp",
           "alone_a.cpp", "alone_b.cpp", "-Wl,-z,defs", "-o", "prog"]
    build = subprocess.run(cmd, cwd=out, capture_output=True, text=True)
    assert build.returncode == 0, build.stderr
    run = subprocess.run([str(out / "prog")], capture_output=True, text=True)
    assert run.returncode == 0, run.stdout
    for line in run.stdout.splitlines():
        name, status, worst = line.split()
        assert status == "0" and float(worst) <= 1e-7, line


@pytest.mark.slow
def test_a_compiler_left_by_a_killed_build_cannot_write_into_the_next_ones_object(tmp_path):
    """A build killed (SIGKILL) while its solver compiles releases its locks, but the compiler
    it started runs on and writes its output late. The next build's object must not be that
    output: each compile writes under a name of its own."""
    with open(CONFIG) as f:
        real = json.load(f)["compiler"]
    log, ready, done = tmp_path / "outs", tmp_path / "ready", tmp_path / "done"
    cxx = wrapper(tmp_path, f'echo "$$ $out" >> {log}\n'
                            f'if [ -n "$HANG" ]; then exec sleep 60; fi\n'
                            f'{real} "$@" || exit 1; touch {ready}\n'
                            f'while [ ! -e {done} ]; do sleep 0.1; done; exit 0')
    env = env_for(tmp_path, toolchain_dir(tmp_path, compiler=cxx))
    first = subprocess.Popen([PY, "-m", "chaincomp.cli.main", "build", variant(str(tmp_path), "killed_a")],
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=dict(env, HANG="1"), cwd=ROOT)
    try:
        for _ in range(600):
            if log.exists() and log.read_text().strip():
                break
            first.poll()
            assert first.returncode is None, "the first build ended before its solver compile"
            time.sleep(0.1)
        first.kill()  # the build, not its compiler: that one runs on
        first.wait()
        orphan_pid, orphan_out = log.read_text().split()
        second = subprocess.Popen([PY, "-m", "chaincomp.cli.main", "build", variant(str(tmp_path), "killed_b", h=440)],
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=ROOT)
        for _ in range(1200):
            if ready.exists() or second.poll() is not None:
                break
            time.sleep(0.1)
        # the left compiler's late output, while the second build's compile ends
        with open(orphan_out, "wb") as f:
            f.write(b"half an object of the killed build")
        done.touch()
        out, err = second.communicate(timeout=600)
    finally:
        done.touch()
        if 'orphan_pid' in locals():
            os.kill(int(orphan_pid), signal.SIGKILL)  # the left compiler (a sleep), by its id
    assert second.returncode == 0, err
    assert_compensates(load(out.strip()))
