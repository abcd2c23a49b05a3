"""chaincomp budget's bad input: an empty --params value is refused, not run with every error zero."""

from __future__ import annotations

import pytest

from helpers import VMC, refused


@pytest.mark.parametrize("argv", [["budget", VMC]])
def test_an_empty_params_value_is_refused(capsys, argv):
    """--params '' ran with every error zero (common.values_for read it as no params file)."""
    refused(capsys, *argv, "--params", "",
             match="--params: an empty value (leave the option out for no error values)")
