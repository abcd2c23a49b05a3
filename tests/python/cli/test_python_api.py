"""The Python API: the README's example runs and prints the paper's Table 3 row; values
default sensibly and a misspelt name is refused."""

import os
import re
import subprocess
import sys

import numpy as np
import pytest

import chaincomp
from helpers import ROOT



def readme_example() -> str:
    text = open(os.path.join(ROOT, "README.md"), encoding="utf-8").read()
    section = text[text.index("## From Python"):]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


@pytest.mark.slow
def test_readme_example_reproduces_table3_and_truncation_order():
    proc = subprocess.run([sys.executable, "-c", readme_example()], cwd=ROOT, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    # Freeman & Ford (2003) Table 3, first row (A = 30°, C = 40°): 13.144206, 6.252881, -18.427610
    got = [float(v) for v in lines[0].strip("[]").split(",")]
    assert got == pytest.approx([13.144206, 6.252881, -18.427610], abs=1e-6)
    r1, r2 = (float(l.split()[1]) for l in lines[1:3])
    assert r2 < r1 / 50      # the second-order residual is far below the first-order one
    assert lines[-1] == "[]"


def test_constants_default_to_nominal_and_errors_to_zero():
    m = chaincomp.load_machine(os.path.join(ROOT, "configs/machines/angle_head.yaml"))
    axes = {"Ap": 0.3, "Cp": -1.1}
    full = {s.name: s.to_internal(s.nominal) for s in m.constants} | {s.name: 0.0 for s in m.errors} | axes
    exact = chaincomp.ExactModel(m)
    assert np.allclose(exact.pose(axes)[0], exact.pose(full)[0], rtol=0, atol=0)
    dp, _ = exact.error(axes)
    assert max(abs(v) for v in dp) == 0.0


def test_missing_axis_and_unknown_name_refused():
    m = chaincomp.load_machine(os.path.join(ROOT, "configs/machines/angle_head.yaml"))
    exact = chaincomp.ExactModel(m)
    with pytest.raises(chaincomp.ChaincompError, match="no value for axis 'Cp'"):
        exact.pose({"Ap": 0.1})
    with pytest.raises(chaincomp.ChaincompError, match="unknown symbol 'Oxc'"):
        exact.error({"Ap": 0.1, "Cp": 0.2, "Oxc": 1e-3})


def test_public_names_documented():
    for name in chaincomp.__all__:
        obj = getattr(chaincomp, name)
        assert obj.__doc__, name
