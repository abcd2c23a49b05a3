"""Options with a control character in an integer value: a one-line error, never an internal error."""

from __future__ import annotations

from helpers import VMC, run_main


def test_an_integer_option_with_a_control_character_is_not_an_internal_error(capsys):
    """str.strip() takes '\\x1f' (a unit separator) off, int() does not: '--grid 3\\x1f' passed
    the digits check and int() raised ValueError (exit 3). test_cli_options' property test found it."""
    from chaincomp.cli.common import integer
    assert integer(1, 10)("3\x1f") == 3 and integer(1, 10)(" 4\n") == 4
    code, _, err = run_main(capsys, "protocol", VMC, "--poses", "1\x1f0x")
    assert code == 2 and "argument --poses: expected an integer, got '1\\x1f0x'" in err, err
