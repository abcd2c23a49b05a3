"""One reading of every file: the conformance corpus in tests/conformance/ read by the Python
loaders and by the C++ ones (build/bin/chaincomp_params_dump, the code chaincompd and replay
load with).

Each corpus file states on its first line what a correct reader makes of it, worked out by
hand from YAML 1.1/1.2 and the params format (not from either loader):
``# expect: ok NAME=VALUE ...`` (values in internal units: mm, rad; ``varying=NAME`` for an
error given as a table) or ``# expect: LINE: FIELD: message`` (the refusal after ``FILE:``).
params/ files are read by both loaders, which must agree with each other and with that line;
thermal/ files (thermal models: ``# expect: ok ref=T NAME:OFFSET[:SENSOR:GAIN:TAU]...`` in internal
units per K and s) are read by both loaders too; config/ files (runtime settings, read only by C++) and tolerances/ files (read only by Python,
through the same YAML rules and value grammar) must match it.
"""

from __future__ import annotations

import glob
import os
import subprocess

import pytest

from chaincomp.errors import ChaincompError
from chaincomp.model.machine import load_machine
from chaincomp.model.params import load_params
from chaincomp.analysis.tolerances import load_tolerances
from chaincomp.measure.thermal import load_model as load_thermal
from chaincomp.model.varying import Varying
from helpers import ROOT

CORPUS = os.path.join(ROOT, "tests", "conformance")
DUMP = os.path.join(ROOT, "build", "bin", "chaincomp_params_dump")
MACHINE = "five_axis_ac"


def _expect(path: str) -> str:
    with open(path, "rb") as f:  # some files are not UTF-8 past their first line
        first = f.readline().decode("utf-8")
    assert first.startswith("# expect: "), f"{path}: first line must say what to expect"
    return first[len("# expect: "):].rstrip("\n")


def _cpp(kind: str, path: str) -> tuple[int, str, str]:
    if not os.path.exists(DUMP):
        pytest.skip("build/bin/chaincomp_params_dump not built (tools/setup)")
    proc = subprocess.run([DUMP, MACHINE, kind, path], capture_output=True, text=True, timeout=60)
    return proc.returncode, proc.stdout, proc.stderr.strip()


def _python(path: str, machine):
    try:
        return load_params(path, machine), None
    except ChaincompError as exc:
        return None, str(exc)


@pytest.fixture(scope="module")
def machine():
    return load_machine(os.path.join(ROOT, "configs", "machines", f"{MACHINE}.yaml"))


def _files(kind):
    return sorted(glob.glob(os.path.join(CORPUS, kind, "*.yaml")))


@pytest.mark.parametrize("path", _files("params"), ids=lambda p: os.path.basename(p)[:-5])
def test_both_loaders_read_the_corpus_alike(path, machine):
    expect = _expect(path)
    py_values, py_error = _python(path, machine)
    rc, out, err = _cpp("params", path)
    if not expect.startswith("ok"):
        want = f"{path}:{expect}"
        assert py_error == want, "Python"
        assert (rc, err) == (2, want), "C++"
        return
    assert py_error is None and rc == 0, (py_error, err)
    cpp = {}
    for line in out.splitlines():
        name, value = line.split(" ", 1)
        if name == "varying":
            cpp.setdefault("varying", set()).add(value)
        else:
            cpp[name] = float(value)
    for item in expect.split()[1:]:
        name, value = item.split("=")
        if name == "varying":
            assert isinstance(py_values[value], Varying) and value in cpp["varying"]
            continue
        # the same double from both, and the hand-worked value (to rounding of the unit factor)
        assert py_values[name] == cpp[name], name
        assert cpp[name] == pytest.approx(float(value), rel=1e-15, abs=0), name
    # nothing read that the file does not say
    listed = {i.split("=")[0] for i in expect.split()[1:]} | set(py_values)
    for name, value in cpp.items():
        if name != "varying" and name not in listed and machine.symbol(name).role == "error":
            assert value == 0.0, name


@pytest.mark.parametrize("path", _files("config"), ids=lambda p: os.path.basename(p)[:-5])
def test_runtime_config_corpus(path):
    expect = _expect(path)
    rc, out, err = _cpp("config", path)
    if expect.startswith("ok"):
        assert rc == 0 and out.splitlines()[0] == "ok", err
        values = dict(line.split(" ") for line in out.splitlines()[1:])
        for item in expect.split()[1:]:  # NAME=VALUE: the value read (mm)
            name, value = item.split("=")
            assert float(values[name]) == float(value), name
    else:
        assert (rc, err) == (2, f"{path}:{expect}")


@pytest.mark.parametrize("path", _files("tolerances"), ids=lambda p: os.path.basename(p)[:-5])
def test_tolerance_corpus(path, machine):
    expect = _expect(path)
    try:
        bounds = {t.name: t.bound for t in load_tolerances(path, machine).items}
    except ChaincompError as exc:
        assert str(exc) == f"{path}:{expect}"
        return
    assert expect.startswith("ok"), bounds
    for item in expect.split()[1:]:
        name, value = item.split("=")
        assert bounds[name] == pytest.approx(float(value), rel=1e-15, abs=0), name


@pytest.mark.parametrize("path", _files("thermal"), ids=lambda p: os.path.basename(p)[:-5])
def test_both_loaders_read_the_thermal_corpus_alike(path, machine):
    expect = _expect(path)
    try:
        model, py_error = load_thermal(path, machine), None
    except ChaincompError as exc:
        model, py_error = None, str(exc)
    rc, out, err = _cpp("thermal", path)
    if not expect.startswith("ok"):
        want = f"{path}:{expect}"
        assert py_error == want, "Python"
        assert (rc, err) == (2, want), "C++"
        return
    assert py_error is None and rc == 0, (py_error, err)
    lines = out.split("\n")
    assert lines[0] == f"reference {model.reference!r}" or float(lines[0].split()[1]) == model.reference
    cpp = {}
    for line in lines[1:]:
        if line:
            name, offset, *terms = line.split()
            cpp[name] = (float(offset), [(t.split(":")[0], float(t.split(":")[1]), float(t.split(":")[2])) for t in terms])
    py = {n: (em.offset * em.unit.to_internal, [(t.sensor, t.gain * em.unit.to_internal, t.time_constant) for t in em.terms])
          for n, em in model.errors.items()}
    assert py == cpp   # the same doubles from both
    tokens = expect.split()[1:]
    assert float(tokens[0].split("=")[1]) == model.reference
    for token in tokens[1:]:   # and the hand-worked values
        name, offset, *rest = token.split(":")
        assert cpp[name][0] == pytest.approx(float(offset), rel=1e-15, abs=0), name
        want = [(rest[i], float(rest[i + 1]), float(rest[i + 2])) for i in range(0, len(rest), 3)]
        for (s, g, tau), (ws, wg, wtau) in zip(cpp[name][1], want):
            assert (s, tau) == (ws, wtau) and g == pytest.approx(wg, rel=1e-15, abs=0), name
        assert len(cpp[name][1]) == len(want), name
    assert sorted(cpp) == sorted(t.split(":")[0] for t in tokens[1:])
