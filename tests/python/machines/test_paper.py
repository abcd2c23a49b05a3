"""Freeman & Ford (2003), Tables 2 and 3, against the chain of configs/machines/angle_head.yaml.

Values typed in from the paper: J. M. Freeman and D. G. Ford, Proc. IMechE Part C 217(9),
2003, pp. 1077-1084.
"""

import math

import pytest
import sympy as sp

from chaincomp import load_machine
from chaincomp.symbolic.derive import derive

from helpers import eval_json, machine_path

# Table 3: A (deg), C (deg), computer X, Y, Z (mm), with G = 20 mm, e = 10 mm, Yp = 50°.
TABLE3 = [
    (30, 40, 13.144206, 6.252881, -18.427610),
    (20, 50, 11.483648, 7.204478, -19.292204),
    (10, 90, 10.149614, 12.660444, -19.821696),
]


@pytest.mark.parametrize("a, c, x, y, z", TABLE3)
def test_table3_through_eval(a, c, x, y, z):
    out = eval_json(machine_path("angle_head"), "--set", f"Ap={a}", "--set", f"Cp={c}")
    e, yp = 10.0, math.radians(50.0)
    # Table 3's origin is shifted from the A/C intersection by (0, e, e/tan Yp) (§4.1).
    shifted = [out["position"][0], out["position"][1] + e, out["position"][2] + e / math.tan(yp)]
    # The paper prints six decimals: agreement to that rounding (5e-7) plus float slack.
    for got, want in zip(shifted, (x, y, z)):
        assert abs(got - want) < 1e-6


def test_table2_nominal_symbolically():
    m = load_machine(machine_path("angle_head"))
    d = derive(m, 1)
    G, Yp, e, A, C = (m.symbol(n).sym for n in ("G", "Yp", "e", "Ap", "Cp"))
    sin, cos, tan = sp.sin, sp.cos, sp.tan
    Y = Yp
    # Table 2, typed in as printed.
    X = (G * sin(Y) * sin(A) * cos(C) - G * sin(Y) * cos(A) * cos(Y) * sin(C)
         + G * cos(Y) * sin(Y) * sin(C) + e * sin(C))
    Yv = (G * sin(Y) * sin(A) * sin(C) + G * sin(Y) * cos(A) * cos(Y) * cos(C)
          - G * cos(Y) * sin(Y) * cos(C) - e * cos(C))
    Z = -G * sin(Y) * cos(A) * sin(Y) - G * cos(Y) * cos(Y) - e / tan(Y)
    for i, printed in enumerate((X, Yv, Z)):
        assert sp.simplify(d.nominal(d.point[i]) - printed) == 0


def test_table2_dx_first_order_symbolically():
    """Table 2's DX agrees term by term with the chain (DY and DZ hold slips: see the checker)."""
    m = load_machine(machine_path("angle_head"))
    d = derive(m, 1)
    s = {n: m.symbol(n).sym for n in ("G", "Yp", "e", "Ap", "Cp", "ThetaAs", "Oas", "ThetaAv", "DY",
                                         "Ocx", "Ocy", "ThetaCh")}
    G, Y, e, A, C = s["G"], s["Yp"], s["e"], s["Ap"], s["Cp"]
    As, Oas, Av, DY, Ocx, Ocy, Ch = (s[n] for n in ("ThetaAs", "Oas", "ThetaAv", "DY", "Ocx", "Ocy", "ThetaCh"))
    sin, cos, tan = sp.sin, sp.cos, sp.tan
    DX = (G * As * cos(A) * cos(C) - G * cos(Y) * Av * cos(A) * cos(C) + Oas * cos(Y) * sin(A) * cos(C)
          - G * cos(Y) * DY * sin(A) * cos(C) + Ocx * cos(C) + G * As * sin(A) * cos(Y) * sin(C)
          - G * cos(Y) * Av * sin(A) * cos(Y) * sin(C) - Oas * cos(Y) * cos(A) * cos(Y) * sin(C)
          + G * cos(Y) * DY * cos(A) * cos(Y) * sin(C) + G * sin(Y) * DY * sin(Y) * sin(C)
          - Oas * sin(Y) * sin(Y) * sin(C) - Ocy * sin(C) - G * sin(Y) * cos(A) * sin(Y) * Ch
          - G * cos(Y) * cos(Y) * Ch - e / tan(Y) * Ch)
    assert sp.simplify(d.error(d.point[0]) - DX) == 0
