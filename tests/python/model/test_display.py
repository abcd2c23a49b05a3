"""chaincomp.model.display: units for people and estimate ± uncertainty, against hand-worked rounding.

Rule (GUM 7.2.6 practice): the uncertainty to 2 significant digits, the estimate to the same
decimal place. Each expectation below was rounded by hand from the decimal text of the inputs."""

import argparse
import math

import pytest

from chaincomp.model.display import DEFAULT_UNITS, add_units_argument, convert, display_unit, plus_minus, quantity, uncertain


@pytest.mark.parametrize("value, u, text", [
    (4.6012, 0.2149, "4.60 ± 0.21"),
    (0.0996, 0.0041, "0.0996 ± 0.0041"),
    (-0.0996, 0.0041, "-0.0996 ± 0.0041"),
    (0.09962, 0.00415, "0.0996 ± 0.0042"),       # half away from zero on the decimal text 0.00415
    (0.0996, 0.00996, "0.100 ± 0.010"),          # u rounds up to 0.010: still two significant digits
    (12.3456, 0.995, "12.3 ± 1.0"),
    (-0.001, 0.21, "0.00 ± 0.21"),               # no '-0.00'
    (0.0, 0.1, "0.00 ± 0.10"),
    (123456.7, 2345.0, "123500 ± 2300"),
    (0.000321, 0.0000123, "0.000321 ± 0.000012"),
    (2.675, 0.015, "2.675 ± 0.015"),             # binary 2.675 is 2.67499..., the decimal text is not
])
def test_plus_minus_rounds_the_uncertainty_to_two_digits_and_the_estimate_to_its_place(value, u, text):
    assert plus_minus(value, u) == text


@pytest.mark.parametrize("value, u, text", [
    (1.234e-9, 5.6e-11, "(1.234 ± 0.056)e-09"),     # tiny: a shared exponent
    (-1.234e-9, 5.6e-11, "(-1.234 ± 0.056)e-09"),
    (1.23456789e9, 1.2e7, "(1.235 ± 0.012)e+09"),   # huge
    (3.0e-12, 4.44e-7, "(0.0 ± 4.4)e-07"),          # the uncertainty sets the exponent when it is larger
])
def test_plus_minus_outside_the_plain_range_shares_one_exponent(value, u, text):
    assert plus_minus(value, u) == text


def test_plus_minus_edge_cases():
    assert plus_minus(5.0, 0.0) == "5 ± 0"
    assert plus_minus(2.5, math.inf) == "2.5 ± inf"
    with pytest.raises(ValueError):
        plus_minus(1.0, -0.1)


def test_people_units_are_um_arcsec_and_um_per_m():
    assert display_unit("length").name == "µm" and display_unit("angle").name == "arcsec"
    assert display_unit("ratio").name == "µm/m"
    assert display_unit("length", "internal").name == "mm" and display_unit("angle", "internal").name == "rad"
    v, name = convert(math.radians(1.0 / 3600.0), "angle")
    assert name == "arcsec" and v == pytest.approx(1.0, rel=1e-15)
    assert convert(0.0046, "length") == (pytest.approx(4.6, rel=1e-15), "µm")
    assert convert(3e-6, "ratio") == (pytest.approx(3.0, rel=1e-15), "µm/m")


def test_uncertain_and_quantity_convert_from_internal_units():
    assert uncertain(0.0046012, 0.0002149, "length") == "4.60 ± 0.21 µm"
    assert uncertain(0.0046012, 0.0002149, "length", "internal") == "0.00460 ± 0.00021 mm"
    arcsec = math.pi / 648000
    assert uncertain(12.34 * arcsec, 0.56 * arcsec, "angle") == "12.34 ± 0.56 arcsec"
    assert quantity(0.0024047719, "length") == "2.405 µm"        # 1 nm resolution
    assert quantity(-0.0024047719, "length", "internal") == "-0.002404772 mm"
    assert quantity(-1e-12, "length") == "0.000 µm"
    assert quantity(10 * arcsec, "angle") == "10.000 arcsec"


def test_one_units_option():
    p = argparse.ArgumentParser()
    add_units_argument(p)
    assert p.parse_args([]).units == DEFAULT_UNITS == "people"
    assert p.parse_args(["--units", "internal"]).units == "internal"
    with pytest.raises(SystemExit):
        p.parse_args(["--units", "imperial"])
