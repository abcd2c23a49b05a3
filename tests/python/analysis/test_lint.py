"""Model lint: an error or axis that never moves the tool is named with its line, exit 0
(exit 2 with --strict); every bundled machine lints clean. Whether a symbol moves the tool
is decided here by hand from the geometry, not by the code under test."""

import glob
import os

import pytest

from helpers import ROOT, cli, line_of, run_cli


# A rotary table C with a point on it at radius R, then an error rotation ez about the
# tool point's own z axis (cannot move a point), and a slide X along the chain.
MACHINE = """\
name: lint_case
rotation_sense: right_hand
error_block_order: txyz
symbols:
  - {name: C, role: axis, unit: deg, limits: [-180, 180]}
  - {name: X, role: axis, unit: mm, limits: [-100, 100]}
  - {name: R, role: constant, unit: mm, nominal: 50}
  - {name: dx, role: error, unit: um}
  - {name: ez, role: error, unit: arcsec}
chain:
  - {translate: [X, 0, 0]}
  - {rotate: z, angle: C}
  - {translate: [R, 0, 0]}
  - {errors: {dx: dx, ez: ez}}
tool:
  point: [0, 0, 0]
"""


def run(*args):
    """In this process (cli.main.main), without a process's ~1 s of start-up."""
    return cli(*args, check=False)


def write(tmp_path, text):
    path = tmp_path / "m.yaml"
    path.write_text(text)
    return path


def test_error_that_cannot_move_the_point(tmp_path):
    path = write(tmp_path, MACHINE)
    proc = run_cli("lint", str(path), check=False)   # real processes here: the exit path (0, and 2 with --strict)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith(f"chaincomp lint: warning: {path}:{line_of(MACHINE, '{name: ez')}: symbols.ez: "
                               f"error ez never moves the tool point: its gain is zero at every pose "
                               f"(line {line_of(MACHINE, '{errors:')})"), lines[0]
    strict = run_cli("lint", "--strict", str(path), check=False)
    assert strict.returncode == 2 and "1 warning (--strict)" in strict.stderr, strict.stderr
    # every verb that loads the machine prints it too, and still works
    proc = run("derive", str(path))
    assert proc.returncode == 0 and "symbols.ez: error ez never moves" in proc.stderr, proc.stderr


def test_axis_that_cannot_move_the_point(tmp_path):
    # the point on the rotary axis itself: C turns it about itself
    text = MACHINE.replace("[R, 0, 0]}", "[0, 0, R]}").replace("{dx: dx, ez: ez}", "{dx: dx}") \
                  .replace("  - {name: ez, role: error, unit: arcsec}\n", "")
    path = write(tmp_path, text)
    proc = run("lint", str(path))
    assert proc.returncode == 0
    assert f"{path}:{line_of(text, '{name: C')}: symbols.C: axis C never moves the tool point" in proc.stderr, \
        proc.stderr
    # with a tool direction along x, C turns the direction: no warning
    proc = run("lint", str(write(tmp_path, text.replace("point: [0, 0, 0]", "point: [0, 0, 0]\n  direction: [1, 0, 0]"))))
    assert proc.returncode == 0 and "never moves" not in proc.stderr, proc.stderr


def test_unobservable_marks(tmp_path):
    text = MACHINE.replace("{name: ez, role: error, unit: arcsec}", "{name: ez, role: error, unit: arcsec, unobservable: true}")
    assert run("lint", "--strict", str(write(tmp_path, text))).returncode == 0
    text = MACHINE.replace("{name: dx, role: error, unit: um}", "{name: dx, role: error, unit: um, unobservable: true}")
    proc = run("lint", str(write(tmp_path, text)))
    assert "symbols.dx.unobservable: error dx is marked unobservable but moves the tool point" in proc.stderr, \
        proc.stderr
    text = MACHINE.replace("{name: X, role: axis, unit: mm,", "{name: X, role: axis, unit: mm, unobservable: true,")
    proc = run("lint", str(write(tmp_path, text)))
    assert proc.returncode == 2 and "symbols.X.unobservable: only an error symbol" in proc.stderr, proc.stderr


@pytest.mark.parametrize("path", sorted(glob.glob(os.path.join(ROOT, "configs", "machines", "*.yaml"))),
                         ids=os.path.basename)
def test_bundled_machines_lint_clean(path):
    proc = run("lint", "--strict", path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""


def test_a_turn_about_the_tool_axis_moves_only_a_tool_frame(tmp_path):
    # ez turns about the tool point's own z: with direction z it moves neither point nor
    # direction, but a frame's x axis turns with it
    direction = MACHINE.replace("point: [0, 0, 0]", "point: [0, 0, 0]\n  direction: [0, 0, 1]")
    proc = run("lint", str(write(tmp_path, direction)))
    assert proc.returncode == 0
    assert "symbols.ez: error ez never moves the tool point or direction" in proc.stderr, proc.stderr
    frame = direction.replace("direction: [0, 0, 1]", "direction: [0, 0, 1]\n  reference: [1, 0, 0]")
    proc = run("lint", "--strict", str(write(tmp_path, frame)))
    assert proc.returncode == 0 and "warning" not in proc.stderr, proc.stderr
    # marked unobservable, as a spindle's turn is without a frame: with one it is seen
    marked = frame.replace("{name: ez, role: error, unit: arcsec}", "{name: ez, role: error, unit: arcsec, unobservable: true}")
    proc = run("lint", str(write(tmp_path, marked)))
    assert "symbols.ez.unobservable: error ez is marked unobservable but moves the tool frame" in proc.stderr, \
        proc.stderr
    # ez turned back by a later -ez: it moves nothing, the frame included
    dz = frame.replace("{errors: {dx: dx, ez: ez}}", "{errors: {dx: dx, ez: ez}}\n  - {rotate: z, angle: -ez}")
    proc = run("lint", str(write(tmp_path, dz)))
    assert "symbols.ez: error ez never moves the tool frame (point and orientation)" in proc.stderr, proc.stderr
