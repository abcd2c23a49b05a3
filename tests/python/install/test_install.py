"""The installable products (issue #28 item 4): `cmake --install build --prefix P` lays out the
programs, the headers and chaincomp's CMake package; a project outside the tree
(tests/install/consumer) finds it with find_package(chaincomp), compiles models written by
`chaincomp generate` and links chaincomp::compensator, and its corrections put the actual tool
point on the nominal one as the Python model (ExactModel, evaluated here) computes them; the
Python package builds into a wheel whose `chaincomp` entry point runs. The version is checked
everywhere against codegen/chaincomp/__init__.py, read as text."""

import json
import math
import os
import re
import shutil
import subprocess
import zipfile

import pytest

from helpers import PARAMS, PY, ROOT, machine_path

pytestmark = pytest.mark.slow

BUILD = os.path.join(ROOT, "build")
CONSUMER = os.path.join(ROOT, "tests", "install", "consumer")
with open(os.path.join(ROOT, "codegen", "chaincomp", "__init__.py"), encoding="utf-8") as _f:
    VERSION = re.search(r'^__version__ = "([^"]+)"$', _f.read(), re.M).group(1)

# A machine of the test's own (three axes, two of them angular in deg): a SCARA-like arm.
SCARA = """\
name: scara_t
description: a SCARA-like arm written by the install test
length_unit: mm
rotation_sense: right_hand
error_block_order: txyz
symbols:
  - {name: q1, role: axis, unit: deg, limits: [-150, 150]}
  - {name: q2, role: axis, unit: deg, limits: [-140, 140]}
  - {name: Z, role: axis, unit: mm, limits: [-200, 0]}
  - {name: a1, role: constant, unit: mm, nominal: 325}
  - {name: a2, role: constant, unit: mm, nominal: 275}
  - {name: d1, role: error, unit: arcsec}
  - {name: da1, role: error, unit: um}
  - {name: d2, role: error, unit: arcsec}
  - {name: da2, role: error, unit: um}
  - {name: tilt, role: error, unit: arcsec}
  - {name: dz, role: error, unit: um}
chain:
  - {rotate: z, angle: q1}
  - {errors: {ez: d1}}
  - {translate: [a1, 0, 0]}
  - {errors: {dx: da1, ex: tilt}}
  - {rotate: z, angle: q2}
  - {errors: {ez: d2}}
  - {translate: [a2, 0, 0]}
  - {errors: {dx: da2}}
  - {translate: [0, 0, Z]}
  - {errors: {dz: dz}}
tool:
  point: [0, 0, 0]
"""
# declared units (arcsec, um); a constant too: the consumer takes any parameter
SCARA_VALUES = {"d1": 20.0, "da1": 10.0, "d2": -15.0, "da2": 5.0, "tilt": 10.0, "dz": 3.0, "a2": 275.02}


def run(cmd, **kw) -> subprocess.CompletedProcess:
    proc = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, **kw)
    assert proc.returncode == 0, f"{' '.join(map(str, cmd))} exited {proc.returncode}:\n{proc.stdout}\n{proc.stderr}"
    return proc


def venv_site() -> str:
    """The venv's site-packages: the lcm wheel's CMake package lies below it (tools/setup)."""
    return run([PY, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"]).stdout.strip()


@pytest.fixture(scope="module")
def prefix(tmp_path_factory) -> str:
    if not os.path.isfile(os.path.join(BUILD, "CMakeCache.txt")):
        pytest.skip("build/ is missing (tools/setup configures and builds it)")
    p = tmp_path_factory.mktemp("prefix")
    run(["cmake", "--install", BUILD, "--prefix", p])
    return str(p)


@pytest.fixture(scope="module")
def consumer(prefix, tmp_path_factory) -> dict:
    """tests/install/consumer configured against the installed prefix and built once, with a
    bundled machine and the test's own: {machine name: (machine file, correct_NAME program)}."""
    work = tmp_path_factory.mktemp("consumer")
    scara = work / "scara_t.yaml"
    scara.write_text(SCARA, encoding="utf-8")
    machines = {"vmc_xyz": machine_path("vmc_xyz"), "scara_t": str(scara)}
    gen = work / "generated"
    run([PY, "-m", "chaincomp.cli.main", "generate", *machines.values(), "-o", gen], cwd=work)
    sources = ";".join(str(gen / f"{name}.cpp") for name in machines)
    build = work / "build"
    configured = run(["cmake", "-S", CONSUMER, "-B", build, "-DCMAKE_BUILD_TYPE=Release",
                      f"-DCMAKE_PREFIX_PATH={prefix};{venv_site()}", f"-DCHAINCOMP_MODELS={sources}"])
    # found in the prefix, not in the build tree
    assert f"chaincomp {VERSION.split('-')[0]}" in configured.stdout, configured.stdout
    assert os.path.join(prefix, "lib", "cmake", "chaincomp") in configured.stdout, configured.stdout
    run(["cmake", "--build", build, "-j2"])
    return {name: (path, str(build / f"correct_{name}")) for name, path in machines.items()}


# ----------------------------------------------------------------------------- (a) the prefix

def test_install_lays_out_programs_headers_and_cmake_package(prefix):
    for rel in ("bin/chaincompd", "bin/chaincomp_replay"):
        assert os.access(os.path.join(prefix, rel), os.X_OK), rel
    for header in ("compensate.hpp", "compensator.hpp", "model_info.hpp", "trig.hpp", "varying.hpp"):
        assert os.path.isfile(os.path.join(prefix, "include", "chaincomp", header)), header
    for msg in ("lcmt_axis_command", "lcmt_corrected_target", "lcmt_chaincomp_control", "lcmt_chaincomp_status"):
        assert os.path.isfile(os.path.join(prefix, "include", "chaincomp_lcm", msg + ".hpp")), msg
    cmake_dir = os.path.join(prefix, "lib", "cmake", "chaincomp")
    for f in ("chaincompConfig.cmake", "chaincompConfigVersion.cmake", "chaincompTargets.cmake"):
        assert os.path.isfile(os.path.join(cmake_dir, f)), f
    for lib in ("libchaincomp_core.a", "libchaincomp_compensator.a"):
        assert os.path.isfile(os.path.join(prefix, "lib", lib)), lib
    with open(os.path.join(cmake_dir, "chaincompConfigVersion.cmake"), encoding="utf-8") as f:
        assert f'set(PACKAGE_VERSION "{VERSION.split("-")[0]}")' in f.read()
    with open(os.path.join(cmake_dir, "chaincompConfig.cmake"), encoding="utf-8") as f:
        assert f'set(chaincomp_GENERATOR_VERSION "{VERSION}")' in f.read()
    # the installed programs run from the prefix (liblcm found through their run path)
    for prog in ("chaincompd", "chaincomp_replay"):
        out = run([os.path.join(prefix, "bin", prog), "--version"]).stdout
        assert out == f"{prog} {VERSION}\n"


# ----------------------------------------------------------------------------- (b) a consumer

def correct(program: str, axes, values: dict) -> dict:
    proc = run([program, *(repr(float(a)) for a in axes), *(f"{k}={v!r}" for k, v in values.items())])
    return json.loads(proc.stdout)


def tool_points(path: str, commanded, corrected, values: dict):
    """From the Python model (the chain multiplied numerically): the nominal tool point at the
    command (the constants given, every error 0), and the actual one (the errors too) at the
    command and at the corrected axes."""
    from chaincomp import ExactModel, load_machine
    m = load_machine(path)
    unit = {s.name: s.unit.to_internal for s in m.symbols}
    errors = {s.name for s in m.errors}
    axes = [s.name for s in m.axes]
    internal = {k: v * unit[k] for k, v in values.items()}

    def at(q, with_errors):
        v = {a: x * unit[a] for a, x in zip(axes, q)}
        v.update({k: x for k, x in internal.items() if with_errors or k not in errors})
        return [float(c) for c in ExactModel(m).pose(v)[0]]
    return at(commanded, False), at(commanded, True), at(corrected, True)


def check_corrections(program, path, poses, values):
    for q in poses:
        out = correct(program, q, values)
        # the point is corrected; three slides cannot correct a tilt, which is reported (residual)
        assert out["status"] in ("ok", "residual") and out["commanded"] == [float(x) for x in q], out
        nominal, uncorrected, corrected = tool_points(path, q, out["corrected"], values)
        before, after = math.dist(uncorrected, nominal), math.dist(corrected, nominal)
        assert before > 2e-3, (q, before)     # the errors move the tool by microns: a real test
        assert after < 1e-6, (q, out, after)  # the corrected command puts it back within 1 nm
        assert out["residual_point_mm"] < 1e-6
        for c, x, y in zip(out["correction"], out["corrected"], q):
            assert c == pytest.approx(x - y, abs=1e-12)


def test_consumer_corrects_a_bundled_machine(consumer):
    from chaincomp import load_machine, load_params
    path, program = consumer["vmc_xyz"]
    m = load_machine(path)
    unit = {s.name: s.unit.to_internal for s in m.symbols}
    # the bundled demo errors, given to the program in their declared units (um, arcsec)
    values = {k: v / unit[k] for k, v in load_params(os.path.join(PARAMS, "vmc_xyz-demo.yaml"), m).items()}
    assert len(values) == 21
    check_corrections(program, path, [(100, 50, -200), (-350, 220, -20), (0, 0, -380), (390, -240, -200)], values)


def test_consumer_corrects_a_machine_of_its_own(consumer):
    path, program = consumer["scara_t"]
    check_corrections(program, path, [(30, 45, -50), (-100, 120, -150), (140, -30, -10), (0, 90, -100)],
                      SCARA_VALUES)


def test_consumer_reports_rejections_and_bad_arguments(consumer):
    _, program = consumer["vmc_xyz"]
    outside = subprocess.run([program, "500", "0", "-100"], capture_output=True, text=True)
    assert outside.returncode == 1 and "out_of_limits" in outside.stderr, outside
    bad = subprocess.run([program, "0", "0", "-100", "NOPE=1"], capture_output=True, text=True)
    assert bad.returncode == 2 and "no parameter NOPE" in bad.stderr, bad
    short = subprocess.run([program, "0"], capture_output=True, text=True)
    assert short.returncode == 2 and "usage: correct_vmc_xyz X[mm] Y[mm] Z[mm]" in short.stderr, short


# ----------------------------------------------------------------------------- (c) the wheel

def test_wheel_installs_the_chaincomp_entry_point(tmp_path):
    # ./codegen built from a copy: setuptools leaves its build/ folder beside the sources
    src = tmp_path / "codegen"
    shutil.copytree(os.path.join(ROOT, "codegen"), src,
                    ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__", ".import_linter_cache"))
    dist = tmp_path / "dist"
    proc = subprocess.run([PY, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-w", str(dist), str(src)],
                          capture_output=True, text=True)
    if "invalid command 'bdist_wheel'" in proc.stdout + proc.stderr:
        pytest.fail("the venv cannot build wheels without isolation: its setuptools has no bdist_wheel "
                    "(setuptools < 70.1 needs the 'wheel' package in .venv; tools/setup installs neither)")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    wheels = os.listdir(dist)
    assert wheels == [f"chaincomp-{VERSION}-py3-none-any.whl"], wheels
    wheel = dist / wheels[0]
    with zipfile.ZipFile(wheel) as z:
        info = f"chaincomp-{VERSION}.dist-info"
        metadata = z.read(f"{info}/METADATA").decode()
        entry_points = z.read(f"{info}/entry_points.txt").decode()
        names = z.namelist()
    assert re.search(r"^Version: (.+)$", metadata, re.M).group(1) == VERSION
    assert re.search(r"^\[console_scripts\]\nchaincomp = chaincomp\.cli\.main:main$", entry_points, re.M), entry_points
    assert "chaincomp/emit/cpp.py" in names and "chaincomp/py.typed" in names

    site = tmp_path / "site"
    run([PY, "-m", "pip", "install", "-q", "--no-deps", "--target", site, wheel])
    # the package from the wheel; its dependencies (sympy, numpy, ...) from the venv
    env = dict(os.environ, PYTHONPATH=str(site))
    script = site / "bin" / "chaincomp"
    where = run([PY, "-c", "import chaincomp; print(chaincomp.__file__)"], env=env, cwd=tmp_path).stdout.strip()
    assert where == str(site / "chaincomp" / "__init__.py")
    assert run([script, "--version"], env=env, cwd=tmp_path).stdout == f"chaincomp {VERSION}\n"
    help_text = run([script, "--help"], env=env, cwd=tmp_path).stdout
    for verb in ("derive", "eval", "generate", "testvectors", "identify", "replay", "plot", "build", "lint",
                 "status", "import-urdf", "budget", "report"):
        assert re.search(rf"^\s+{re.escape(verb)}\s", help_text, re.M), (verb, help_text)
    tree_help = run([PY, "-m", "chaincomp.cli.main", "--help"], cwd=ROOT, env=dict(os.environ, COLUMNS="120"))
    wheel_help = run([script, "--help"], env=dict(env, COLUMNS="120"), cwd=tmp_path)
    assert wheel_help.stdout == tree_help.stdout
    # the installed package generates the same model as the tree
    run([script, "generate", machine_path("vmc_xyz"), "-o", tmp_path / "from_wheel"], env=env, cwd=tmp_path)
    run([PY, "-m", "chaincomp.cli.main", "generate", machine_path("vmc_xyz"), "-o", tmp_path / "from_tree"],
        cwd=ROOT)
    for f in ("vmc_xyz.hpp", "vmc_xyz.cpp"):
        assert (tmp_path / "from_wheel" / f).read_bytes() == (tmp_path / "from_tree" / f).read_bytes(), f
