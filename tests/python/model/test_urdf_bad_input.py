"""chaincomp import-urdf on URDFs a user writes: a cycle through the base, a joint element given
twice, joints named like a measured coordinate."""

from __future__ import annotations

import pytest

from helpers import URDF, cli, edited, line_holding, run_main, write_file


GANTRY = """<?xml version="1.0"?>
<robot name="gantry">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="l3"/><link name="tool"/>
  <joint name="x" type="prismatic">
    <parent link="base"/><child link="l1"/><origin xyz="0.1 0 0"/><axis xyz="1 0 0"/>
    <limit lower="-0.5" upper="0.5" effort="1" velocity="1"/>
  </joint>
  <joint name="y" type="prismatic">
    <parent link="l1"/><child link="l2"/><origin xyz="0 0.2 0"/><axis xyz="0 1 0"/>
    <limit lower="-0.5" upper="0.5" effort="1" velocity="1"/>
  </joint>
  <joint name="z" type="prismatic">
    <parent link="l2"/><child link="l3"/><origin xyz="0 0 0.3"/><axis xyz="0 0 1"/>
    <limit lower="-0.5" upper="0.5" effort="1" velocity="1"/>
  </joint>
  <joint name="kx" type="revolute">
    <parent link="l3"/><child link="tool"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
</robot>
"""


def test_import_urdf_renames_joints_named_like_a_measured_coordinate(capsys, tmp_path):
    """Joints x, y, z became axes x, y, z, which identify and simulate-measurements then refuse
    (a column x would be both the axis and the measured coordinate)."""
    import json

    from chaincomp.measure import table

    from chaincomp.model import urdf
    assert set(urdf.MEASURED_NAMES) == set(table.COLUMNS)
    src, m = tmp_path / "gantry.urdf", tmp_path / "gantry.yaml"
    src.write_text(GANTRY)
    code, _, err = run_main(capsys, "import-urdf", src, "--base", "base", "--tip", "tool", "--errors", "joint-offsets",
                        "--tool-point", "0,0,50", "-o", m)
    assert code == 0, err
    text = m.read_text()
    assert ("# kx, ky, kz, the measured coordinates' names): x -> x_, y -> y_, z -> z_, kx -> kx_\n"
            in text), text
    # the tool point by hand: the origins and the slides add, in metres -> mm (the tip's 50 mm
    # along z, which the rotation kx_ leaves where it is)
    code, out, err = run_main(capsys, "eval", m, "--set", "x_=10", "--set", "y_=-20", "--set", "z_=30",
                          "--set", "kx_=40", "--json")
    assert code == 0, err
    assert json.loads(out)["position"] == pytest.approx([110.0, 180.0, 380.0], abs=1e-9)
    meas = tmp_path / "meas.csv"
    code, _, err = run_main(capsys, "simulate-measurements", m, "--setups", "random:20", "-o", meas)
    assert code == 0, err
    code, out, err = run_main(capsys, "identify", m, meas, "--assume-zero", "kx__zero", "--sigma", "1um")
    assert code == 0, err
    assert "x__zero" in out


# ----------------------------------------------------------------------------- URDF


def _import(tmp_path, text: str, check: bool = False):
    src = write_file(tmp_path, "r.urdf", text)
    return cli("import-urdf", src, "--base", "base", "--tip", "tip", "-o", str(tmp_path / "r.yaml"), check=check)


def test_the_urdf_reference_imports(tmp_path):
    _import(tmp_path, URDF, check=True)
    assert (tmp_path / "r.yaml").exists()


def test_a_cycle_through_the_base_link_is_refused(tmp_path):
    """base -> l1 -> l2 -> tip, and a joint making base the child of tip: every link has one
    parent, so the per-link check passes; the tree has no root. Before, it imported (exit 0)."""
    text = edited(URDF, "</robot>", '  <joint name="c" type="fixed"><parent link="tip"/><child link="base"/>'
                                     "</joint>\n</robot>")
    proc = _import(tmp_path, text)
    assert proc.returncode == 2, proc.stderr
    at = line_holding(text, '<joint name="c"')
    assert (f"r.urdf:{at}: joint c.child: --base 'base' is the child of joint 'c', and the "
            "joints above it come back round to link 'base' (through joint 'j1', line 7): a cycle") in proc.stderr
    assert not (tmp_path / "r.yaml").exists()


def test_a_root_above_the_base_is_no_cycle(tmp_path):
    text = edited(URDF, "</robot>", '  <link name="world"/>\n  <joint name="c" type="fixed"><parent link="world"/>'
                                     '<child link="base"/></joint>\n</robot>')
    assert _import(tmp_path, text).returncode == 0


@pytest.mark.parametrize("element, old, new", [
    ("origin", '<origin xyz="0.1 0 0"/>', '<origin xyz="0.1 0 0"/>\n    <origin xyz="0.2 0 0"/>'),
    ("axis", '<axis xyz="1 1 0"/>', '<axis xyz="1 1 0"/>\n    <axis xyz="0 0 1"/>'),
    ("limit", '<limit lower="-0.2" upper="0.5" effort="1" velocity="1"/>',
     '<limit lower="-0.2" upper="0.5" effort="1" velocity="1"/>\n    <limit lower="-1" upper="1" effort="1" '
     'velocity="1"/>'),
    ("child", '<parent link="l1"/><child link="l2"/>',
     '<parent link="l1"/><child link="l2"/>\n    <child link="tip"/>'),
])
def test_a_joint_element_given_twice_is_refused(tmp_path, element, old, new):
    """yourdfpy takes the first and drops the rest: a second <origin> (a user's correction
    appended below the first) had no effect, without a word."""
    text = edited(URDF, old, new)
    proc = _import(tmp_path, text)
    assert proc.returncode == 2, proc.stderr
    first = line_holding(text, old)            # each second element is written on the next line
    second = first + 1
    assert (f"r.urdf:{second}: joint j2.{element}: joint 'j2' has 2 <{element}> elements (first on line {first}): "
            "a joint has at most one") in proc.stderr
