"""chaincomp import-urdf against truth from outside chaincomp.

- Forward kinematics of the imported UR5 and Panda (example-robot-data's URDFs) against
  Pinocchio, which reads the URDF with its own parser (urdfdom): 1000 random configurations
  within the limits, the tool point to 1e-9 mm and the tip frame's orientation (its three
  axes) to 1e-12 rad, from chaincomp's exact model of the written machine file.
- Every --errors variant: each error's gain (chaincomp's first-order gain matrix, by jets)
  against central finite differences of a numpy chain written here from the URDF's text
  (xml.etree, Rodrigues' formula), with that error perturbed where the mode puts it.
- Refusals: floating, planar and mimic joints, unknown links, a tip not below the base, a
  closed loop, non-finite numbers, DTD/entity and element-count bombs, each one line with
  the file and the line of the element, exit 2.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import math
import os
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import yaml

from chaincomp import load_machine, lint
from chaincomp.cli.main import main as chaincomp_main
from chaincomp.symbolic.jets import JetModel
from chaincomp.symbolic.numeric import ExactModel

from helpers import ROOT, line_of

ROBOTS = os.path.join(ROOT, ".venv", "lib", "python3.11", "site-packages", "cmeel.prefix", "share",
                      "example-robot-data", "robots")
UR5 = os.path.join(ROBOTS, "ur_description", "urdf", "ur5_robot.urdf")
PANDA = os.path.join(ROBOTS, "panda_description", "urdf", "panda.urdf")
ARMS = {"ur5": (UR5, "base_link", "ee_link"), "panda": (PANDA, "panda_link0", "panda_hand_tcp")}
TOOL = (30.0, -20.0, 120.0)   # mm in the tip frame: off every axis, so every joint and error moves it

pin = pytest.importorskip("pinocchio")


def run(*args):
    """chaincomp ARGS in this process: (exit code, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = chaincomp_main([str(a) for a in args])
    return code, out.getvalue(), err.getvalue()


def imported(tmp_path, arm, errors="none", tool=TOOL):
    urdf, base, tip = ARMS[arm]
    out = tmp_path / f"{arm}-{errors}.yaml"
    code, _, err = run("import-urdf", urdf, "--base", base, "--tip", tip, "--errors", errors,
                       "--tool-point", ",".join(map(str, tool)), "-o", out)
    assert code == 0, err
    return str(out)


def random_configurations(machine, n, seed):
    """n configurations within the limits, internal units (rad, mm), by axis name."""
    rng = np.random.default_rng(seed)
    return {a.name: a.to_internal(rng.uniform(*a.limits, n)) for a in machine.axes}


def with_direction(machine, direction):
    return dataclasses.replace(machine, direction=direction)


# ---------------------------------------------------------------- against Pinocchio

def pinocchio_tips(model, data, machine, q, base, tip):
    """At each configuration k of ``q``: k, Pinocchio's tip frame in the base link's frame
    (pin.SE3) and the TOOL point there (mm)."""
    base_id, tip_id = model.getFrameId(base), model.getFrameId(tip)
    for k in range(len(next(iter(q.values())))):
        qk = pin.neutral(model)
        for a in machine.axes:
            qk[model.joints[model.getJointId(a.name)].idx_q] = q[a.name][k]
        pin.framesForwardKinematics(model, data, qk)
        rel = data.oMf[base_id].inverse() * data.oMf[tip_id]
        yield k, rel, 1000.0 * (rel.translation + rel.rotation @ (np.array(TOOL) / 1000.0))


@pytest.mark.parametrize("arm", sorted(ARMS))
def test_forward_kinematics_equals_pinocchio(arm, tmp_path):
    urdf, base, tip = ARMS[arm]
    m = load_machine(imported(tmp_path, arm))
    model = pin.buildModelFromUrdf(urdf)
    data = model.createData()
    q = random_configurations(m, 1000, seed=7)
    # the URDF's limits, from Pinocchio: the sample lies within them (deg limits round at 1e-9 deg)
    for a in m.axes:
        j = model.joints[model.getJointId(a.name)]
        lo, hi = model.lowerPositionLimit[j.idx_q], model.upperPositionLimit[j.idx_q]
        assert lo - 1e-10 <= q[a.name].min() and q[a.name].max() <= hi + 1e-10, a.name
    point, _ = ExactModel(m).pose(q)
    frames = [ExactModel(with_direction(m, d)).pose(q)[1] for d in ((1, 0, 0), (0, 1, 0), (0, 0, 1))]
    worst_point = worst_angle = 0.0
    for k, rel, want_point in pinocchio_tips(model, data, m, q, base, tip):
        got_point = np.array([c[k] for c in point])
        worst_point = max(worst_point, np.abs(got_point - want_point).max())
        got_rotation = np.array([[c[k] for c in axis] for axis in frames]).T   # columns: the tip's x, y, z
        # the angle of the rotation between the two frames
        angle = np.linalg.norm(pin.log3(rel.rotation.T @ got_rotation))
        worst_angle = max(worst_angle, angle)
    assert worst_point < 1e-9, worst_point
    assert worst_angle < 1e-12, worst_angle


@pytest.mark.parametrize("arm", sorted(ARMS))
def test_the_file_lints_clean_round_trips_and_names_its_source(arm, tmp_path):
    path = imported(tmp_path, arm, "all")
    m = load_machine(path)
    assert lint(m) == []
    text = open(path).read()
    urdf, base, tip = ARMS[arm]
    # the path as given, relative to the current folder when the absolute path lies below it
    shown = os.path.relpath(urdf) if not os.path.relpath(urdf).startswith("..") else urdf
    assert text.startswith(f"# Imported from the URDF {shown} by chaincomp ")
    assert f"path {base} -> {tip}" in text.splitlines()[1]
    # the same import again is the same file, byte for byte
    again = imported(tmp_path / ".." / tmp_path.name, arm, "all")
    assert open(again).read() == text
    # joint names are the axis names; limits in degrees as the URDF's radians say
    doc = yaml.safe_load(text)
    tree = ET.parse(urdf).getroot()
    for s in doc["symbols"]:
        if s["role"] != "axis":
            continue
        limit = tree.find(f"joint[@name='{s['name']}']/limit")
        assert s["unit"] == "deg"
        assert s["limits"] == pytest.approx([math.degrees(float(limit.get("lower"))),
                                             math.degrees(float(limit.get("upper")))], abs=1e-9)


def test_a_base_beside_the_chain_by_fixed_joints_is_its_reference(tmp_path, monkeypatch):
    """UR's controller frame 'base' hangs from base_link by a fixed joint (rpy 0 0 -pi), beside
    the chain: as --base, the tool0 pose is Pinocchio's in that frame (not in base_link's)."""
    monkeypatch.chdir(tmp_path)   # the URDF lies outside the current folder: its path as given
    out = tmp_path / "ur5-base.yaml"
    code, _, err = run("import-urdf", UR5, "--base", "base", "--tip", "tool0", "--tool-point", ",".join(map(str, TOOL)),
                       "-o", out)
    assert code == 0, err
    assert open(out).readline().startswith(f"# Imported from the URDF {UR5} by")
    m = load_machine(str(out))
    model = pin.buildModelFromUrdf(UR5)
    data = model.createData()
    q = random_configurations(m, 50, seed=11)
    point, _ = ExactModel(m).pose(q)
    worst = max(np.abs(np.array([c[k] for c in point]) - want).max()
                for k, _, want in pinocchio_tips(model, data, m, q, "base", "tool0"))
    assert worst < 1e-9, worst
    # a base hanging from the chain by a moving joint is still refused
    err = refused(robot(tmp_path)[0], base="c", tip="a")
    assert "and 'c' hangs from it by the revolute joint 'j2' (only fixed joints may)" in err


# ---------------------------------------------------------------- every error mode

def _rot(axis, angle):
    """Right-handed rotation by angle about a unit axis (Rodrigues), 4x4."""
    u = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
    m = np.eye(4)
    m[:3, :3] = np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k
    return m


def _trans(v):
    m = np.eye(4)
    m[:3, 3] = v
    return m


def urdf_chain(urdf, base, tip):
    """The joints base -> tip from the URDF text: (name, type, xyz in mm, rpy, axis)."""
    root = ET.parse(urdf).getroot()
    by_child = {j.find("child").get("link"): j for j in root.findall("joint")}
    out, link = [], tip
    while link != base:
        j = by_child[link]
        o = j.find("origin")
        xyz = [1000 * float(v) for v in (o.get("xyz", "0 0 0") if o is not None else "0 0 0").split()]
        rpy = [float(v) for v in (o.get("rpy", "0 0 0") if o is not None else "0 0 0").split()]
        a = j.find("axis")
        axis = [float(v) for v in (a.get("xyz") if a is not None else "1 0 0").split()]
        out.append((j.get("name"), j.get("type"), xyz, rpy, axis))
        link = j.find("parent").get("link")
    return out[::-1]


def numpy_pose(chain, q, errors, mode, tool):
    """Tool point and direction (tip z) from 4x4 matrices: each joint T(xyz)·Rz·Ry·Rx, then
    (origins) the block T(d)·Rx(ex)·Ry(ey)·Rz(ez), then the motion about / along its axis by
    q plus (joint-offsets) its zero offset. errors: {name: internal value}."""
    t = np.eye(4)
    for name, kind, xyz, (r, p, y), axis in chain:
        t = t @ _trans(xyz) @ _rot((0, 0, 1), y) @ _rot((0, 1, 0), p) @ _rot((1, 0, 0), r)
        if kind == "fixed":
            continue
        e = lambda k: errors.get(f"{name}_{k}", 0.0)  # noqa: E731
        if mode in ("origins", "all"):
            t = t @ _trans([e("dx"), e("dy"), e("dz")]) @ _rot((1, 0, 0), e("ex")) @ _rot((0, 1, 0), e("ey")) \
                @ _rot((0, 0, 1), e("ez"))
        motion = q[name] + (e("zero") if mode in ("joint-offsets", "all") else 0.0)
        if kind == "prismatic":
            t = t @ _trans(motion * np.asarray(axis) / np.linalg.norm(axis))
        else:
            t = t @ _rot(axis, motion)
    return (t @ [*tool, 1.0])[:3], t[:3, 2]


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["none", "joint-offsets", "origins", "all"])
@pytest.mark.parametrize("arm", sorted(ARMS))
def test_error_gains_equal_finite_differences_of_a_numpy_chain(arm, mode, tmp_path):
    m = load_machine(imported(tmp_path, arm, mode))
    urdf, base, tip = ARMS[arm]
    chain = urdf_chain(urdf, base, tip)
    per_joint = {"none": 0, "joint-offsets": 1, "origins": 6, "all": 7}[mode]
    assert len(m.errors) == per_joint * len(m.axes)
    jets = JetModel(m, 1)
    h = 1e-6   # mm, rad
    sample = random_configurations(m, 5, seed=3)
    for k in range(5):
        q = {name: float(v[k]) for name, v in sample.items()}
        # the nominal pose too, so that mode 'none' is checked against something
        p0, d0 = numpy_pose(chain, q, {}, mode, TOOL)
        got_p, got_d = ExactModel(m).pose(q)
        assert np.abs(np.array(got_p, float) - p0).max() < 1e-9
        gains = jets.gains(q)
        for i, err in enumerate(m.errors):
            up = numpy_pose(chain, q, {err.name: h}, mode, TOOL)
            down = numpy_pose(chain, q, {err.name: -h}, mode, TOOL)
            fd = np.concatenate([(up[0] - down[0]) / (2 * h), (up[1] - down[1]) / (2 * h)])
            got = np.array([float(gains[c][i]) for c in ("dx", "dy", "dz", "dkx", "dky", "dkz")])
            assert np.abs(got - fd).max() < 1e-5 + 1e-7 * np.abs(fd).max(), (err.name, got, fd)
            assert np.abs(fd).max() > 1e-3, err.name   # every error moves the off-axis tool point


# ---------------------------------------------------------------- refusals

ROBOT = """<?xml version="1.0"?>
<robot name="r">
  <link name="a"/>
  <link name="b"/>
  <link name="c"/>
  <joint name="j1" type="revolute">
    <parent link="a"/>
    <child link="b"/>
    <origin xyz="0 0 0.1" rpy="0 0 0"/>
    <axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
  <joint name="j2" type="JTYPE">
    <parent link="b"/>
    <child link="c"/>
    <origin xyz="XYZ" rpy="0 0 0"/>
    <axis xyz="1 0 0"/>
    <limit lower="LOWER" upper="1" effort="1" velocity="1"/>MIMIC
  </joint>
</robot>
"""


def robot(tmp_path, jtype="revolute", xyz="0 0.2 0", lower="-1", mimic="", extra="", name="r.urdf"):
    text = ROBOT.replace("JTYPE", jtype).replace("XYZ", xyz).replace("LOWER", lower).replace("MIMIC", mimic)
    text = text.replace("</robot>", extra + "</robot>")
    path = tmp_path / name
    path.write_text(text)
    return path, text


def named(text, name, tag=""):
    """The line of the element (of ``tag``) named ``name``."""
    return line_of(text, f'{tag and "<" + tag + " "}name="{name}"')


def refused(path, *options, base="a", tip="c"):
    code, out, err = run("import-urdf", path, "--base", base, "--tip", tip, *options, "-o", path.parent / "m.yaml")
    assert code == 2 and out == "" and "Traceback" not in err, (code, err)
    assert len(err.strip().splitlines()) == 1, err
    assert not (path.parent / "m.yaml").exists()
    return err.strip()


def test_a_small_robot_imports(tmp_path):
    path, _ = robot(tmp_path)
    code, out, err = run("import-urdf", path, "--base", "a", "--tip", "c", "--errors", "all",
                         "--tool-point", "10,20,30", "-o", tmp_path / "m.yaml", "--format", "json")
    assert code == 0, err
    m = load_machine(str(tmp_path / "m.yaml"))
    assert [a.name for a in m.axes] == ["j1", "j2"]
    # j1 at 30 deg, j2 at 45 deg: the point by hand, Rz(30°)·T(0,200,100)·Rx(45°) applied to (10,20,30)
    c, s = math.cos(math.pi / 4), math.sin(math.pi / 4)
    local = np.array([10, 20 * c - 30 * s, 20 * s + 30 * c]) + [0, 200, 100]
    c, s = math.cos(math.pi / 6), math.sin(math.pi / 6)
    want = [c * local[0] - s * local[1], s * local[0] + c * local[1], local[2]]
    got, _ = ExactModel(m).pose({"j1": math.pi / 6, "j2": math.pi / 4})
    assert np.allclose(np.array(got, float), want, atol=1e-12)


@pytest.mark.parametrize("jtype", ["floating", "planar"])
def test_floating_and_planar_joints_are_refused_with_their_line(jtype, tmp_path):
    path, text = robot(tmp_path, jtype=jtype)
    err = refused(path)
    assert f"{path}:{named(text, 'j2')}: joint j2.type: joint 'j2' is {jtype}" in err, err


def test_a_mimic_joint_is_refused_with_the_mimic_line(tmp_path):
    path, text = robot(tmp_path, mimic='\n    <mimic joint="j1" multiplier="2"/>')
    err = refused(path)
    assert f"{path}:{line_of(text, '<mimic')}: joint j2.mimic: joint 'j2' mimics joint 'j1'" in err


def test_unknown_links_are_refused(tmp_path):
    path, text = robot(tmp_path)
    err = refused(path, tip="nowhere")
    assert f"{path}:{line_of(text, '<robot')}: --tip 'nowhere': no link of that name (links: a, b, c)" in err
    err = refused(path, base="b ")
    assert "--base 'b ': no link of that name" in err


def test_a_joint_naming_an_undefined_link_is_refused(tmp_path):
    path, text = robot(tmp_path, extra='  <joint name="j3" type="fixed"><parent link="c"/><child link="d"/></joint>\n')
    err = refused(path)
    child = line_of(text, '<child link="d"')
    assert f"{path}:{child}: joint j3.child: joint 'j3': its child link 'd' is not defined" \
        in err


def test_a_tip_not_below_the_base_is_refused(tmp_path):
    path, text = robot(tmp_path)
    err = refused(path, base="c", tip="a")
    assert f"{path}:{named(text, 'a', 'link')}: link a: --tip 'a' is not below --base 'c'" in err


def test_a_closed_loop_is_refused(tmp_path):
    loop = ('  <joint name="j3" type="fixed"><parent link="a"/><child link="c"/></joint>\n')
    path, text = robot(tmp_path, extra=loop)
    err = refused(path)
    assert f"{path}:{named(text, 'j3')}: joint j3.child: link 'c' is the child of joints 'j2'" in err
    assert "closed loop" in err


@pytest.mark.parametrize("xyz, lower, what", [
    # URDF numbers are xs:double (XML Schema 1.1 Part 2 §3.3.5): INF and NaN, not inf or nan
    ("0 nan 0", "-1", "origin xyz: 'nan' is not a number (XML Schema double"),
    ("0 inf 0", "-1", "origin xyz: 'inf' is not a number (XML Schema double"),
    ("0 NaN 0", "-1", "origin xyz: nan is not a finite number"),
    ("0 -INF 0", "-1", "origin xyz: -inf is not a finite number"),
    ("0 1e400 0", "-1", "origin xyz: inf is not a finite number"),
    ("0 0", "-1", "origin xyz: expected 3 numbers, got 2"),
    ("0 1e-40 0", "-1", "origin xyz: 1e-40 is below 1e-27 in magnitude (write 0)"),
    ("0 zero 0", "-1", "origin xyz: 'zero' is not a number (XML Schema double"),
    ("0 0 0", "-inf", "limit lower: '-inf' is not a number (XML Schema double"),
    ("0 0 0", "-INF", "limit: -inf is not a finite number"),
    ("0 0 0", "2", "lower limit 2.0 is not below upper limit 1.0"),
])
def test_bad_numbers_are_refused_with_the_line(xyz, lower, what, tmp_path):
    path, text = robot(tmp_path, xyz=xyz, lower=lower)
    err = refused(path)
    needle = f'<origin xyz="{xyz}"' if "origin" in what else f'<limit lower="{lower}"'
    assert f"{path}:{line_of(text, needle)}: " in err and what in err, err


def test_names_that_sanitise_alike_are_refused(tmp_path):
    path, text = robot(tmp_path)
    text = text.replace('name="j1"', 'name="j-2"').replace('name="j2"', 'name="j_2"')
    path.write_text(text)
    err = refused(path)
    assert f"{path}:{named(text, 'j_2')}: joint j_2: joints 'j-2' (line {named(text, 'j-2')}) " \
           "and 'j_2' both give the name 'j_2'" in err


def test_an_entity_bomb_is_refused_before_parsing(tmp_path):
    lol = '<!DOCTYPE r [<!ENTITY a "aaaaaaaaaa">' + "".join(
        f'<!ENTITY a{i} "{("&a%s;" % ("" if i == 1 else i - 1)) * 10}">' for i in range(1, 10)) + "]>\n"
    path = tmp_path / "bomb.urdf"
    path.write_text('<?xml version="1.0"?>\n' + lol + '<robot name="&a9;"><link name="a"/></robot>\n')
    err = refused(path)
    assert f"{path}:2: DOCTYPE declarations are refused" in err


def test_a_two_megabyte_urdf_of_tiny_elements_is_bounded(tmp_path):
    path = tmp_path / "big.urdf"
    body = "".join(f'<link name="l{i}"/>' for i in range(100_000))
    path.write_text(f'<robot name="r">{body}</robot>')
    assert os.path.getsize(path) > 2_000_000
    err = refused(path)
    assert f"{path}: 100001 XML elements (at most 50000)" in err


def test_a_file_too_large_is_refused(tmp_path):
    path = tmp_path / "huge.urdf"
    path.write_text("<robot name='r'>" + " " * (16 * 1024 * 1024) + "</robot>")
    assert "larger than 16 MiB" in refused(path)


def test_xml_syntax_errors_name_the_line(tmp_path):
    path = tmp_path / "broken.urdf"
    path.write_text('<robot name="r">\n  <link name="a">\n</robot>\n')
    assert refused(path).startswith(f"chaincomp import-urdf: error: {path}:3: XML syntax error")


def test_duplicate_names_are_refused(tmp_path):
    path, text = robot(tmp_path, extra='  <link name="b"/>\n')
    err = refused(path)
    second = text[:text.rindex('<link name="b"')].count("\n") + 1
    assert f"{path}:{second}: link b: link 'b' is defined twice (first on line 4)" in err


def test_option_values_are_checked(tmp_path):
    path, _ = robot(tmp_path)
    assert "--tool-point: expected three numbers" in refused(path, "--tool-point", "1,2")
    assert "--tool-point: expected a finite number" in refused(path, "--tool-point", "1,nan,2")
    assert "--tool-direction: must not be zero" in refused(path, "--tool-direction", "0,0,0")
    code, _, err = run("import-urdf", path, "--base", "a", "--tip", "c", "-o", path)
    assert code == 2 and "is also an input" in err


def test_any_axis_continuous_and_prismatic_joints(tmp_path):
    """A continuous joint about (0.3, -0.4, 0.5) (not unit: normalised), a prismatic one along
    (0, 0.6, -0.8), a fixed joint with all three rpy angles: the exact model against the
    numpy chain, and Pinocchio, at random configurations."""
    text = """<robot name="odd">
  <link name="a"/><link name="b"/><link name="c"/><link name="d"/>
  <joint name="turn" type="continuous">
    <parent link="a"/><child link="b"/>
    <origin xyz="0.01 -0.02 0.3" rpy="0.1 -0.2 0.3"/>
    <axis xyz="0.3 -0.4 0.5"/>
  </joint>
  <joint name="slide" type="prismatic">
    <parent link="b"/><child link="c"/>
    <origin xyz="0 0.05 0" rpy="0 0.7 0"/>
    <axis xyz="0 0.6 -0.8"/>
    <limit lower="-0.1" upper="0.25" effort="1" velocity="1"/>
  </joint>
  <joint name="flange" type="fixed">
    <parent link="c"/><child link="d"/>
    <origin xyz="0.001 0.002 0.003" rpy="-1.1 0.4 2.9"/>
  </joint>
</robot>
"""
    urdf = tmp_path / "odd.urdf"
    urdf.write_text(text)
    out = tmp_path / "odd.yaml"
    code, _, err = run("import-urdf", urdf, "--base", "a", "--tip", "d", "--errors", "all", "--tool-point",
                       ",".join(map(str, TOOL)), "-o", out)
    assert code == 0, err
    m = load_machine(str(out))
    assert [(a.name, a.unit.name, a.limits) for a in m.axes] == [("turn", "deg", (-360.0, 360.0)),
                                                                  ("slide", "mm", (-100.0, 250.0))]
    chain = urdf_chain(str(urdf), "a", "d")
    sample = random_configurations(m, 50, seed=5)
    model = pin.buildModelFromUrdf(str(urdf))
    data = model.createData()
    tip = model.getFrameId("d")
    for k in range(50):
        q = {name: float(v[k]) for name, v in sample.items()}
        p, d = ExactModel(m).pose(q)
        want_p, want_d = numpy_pose(chain, q, {}, "none", TOOL)
        assert np.abs(np.array(p, float) - want_p).max() < 1e-9
        assert np.abs(np.array(d, float) - want_d).max() < 1e-12
        qk = np.array([math.cos(q["turn"]), math.sin(q["turn"]), q["slide"] / 1000])  # continuous: cos, sin
        pin.framesForwardKinematics(model, data, qk)
        assert np.abs(1000 * data.oMf[tip].act(np.array(TOOL) / 1000) - want_p).max() < 1e-9


def test_xacro_and_incomplete_joints_are_refused(tmp_path):
    path = tmp_path / "arm.urdf.xacro"
    path.write_text('<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">\n'
                    '  <xacro:include filename="arm.xacro"/>\n</robot>\n')
    assert f"{path}:2: a xacro element: expand the file first" in refused(path)
    path, text = robot(tmp_path, extra='  <joint name="j3" type="fixed"><child link="a"/></joint>\n')
    assert f"{path}:{named(text, 'j3')}: joint j3: joint 'j3' has no <parent link=...>" in refused(path)


def test_a_mimic_joint_off_the_path_does_not_matter(tmp_path):
    """Franka's URDF has one (panda_finger_joint2 mimics panda_finger_joint1): the arm imports."""
    assert "<mimic" in open(PANDA).read()
    assert load_machine(imported(tmp_path, "panda")).name == "panda"


def test_a_cycle_of_joints_is_refused(tmp_path):
    path = tmp_path / "cycle.urdf"
    text = ('<robot name="r">\n  <link name="a"/>\n  <link name="b"/>\n  <link name="c"/>\n'
            '  <joint name="ab" type="fixed"><parent link="a"/><child link="b"/></joint>\n'
            '  <joint name="ba" type="fixed"><parent link="b"/><child link="a"/></joint>\n</robot>\n')
    path.write_text(text)
    err = refused(path, base="c", tip="a")
    assert f"{path}:{named(text, 'ab')}: joint ab: the joints above link 'a' form a cycle through link 'a'" in err


@pytest.mark.parametrize("arm", sorted(ARMS))
def test_tool_reference_gives_the_full_orientation_of_the_tip_frame_as_pinocchio(arm, tmp_path):
    """--tool-reference: a six-DOF tool frame, its x axis the reference's part orthogonal to the
    direction (both in the tip frame); the frame equals Pinocchio's tip rotation times it."""
    urdf, base, tip = ARMS[arm]
    out = tmp_path / f"{arm}-frame.yaml"
    code, _, err = run("import-urdf", urdf, "--base", base, "--tip", tip, "--tool-point", ",".join(map(str, TOOL)),
                       "--tool-direction", "0,1,1", "--tool-reference", "1,1,0.3", "-o", out)
    assert code == 0, err
    assert "  reference: [1.0, 1.0, 0.3]" in out.read_text().splitlines()
    m = load_machine(str(out))
    z0 = np.array([0, 1, 1]) / math.sqrt(2)
    x0 = np.array([1, 1, 0.3]) - np.dot([1, 1, 0.3], z0) * z0
    x0 /= np.linalg.norm(x0)
    tool = np.column_stack([x0, np.cross(z0, x0), z0])       # the tool frame in the tip frame
    model = pin.buildModelFromUrdf(urdf)
    data = model.createData()
    q = random_configurations(m, 300, seed=11)
    point, direction, x_axis = ExactModel(m).frame(q)
    worst_point = worst_angle = 0.0
    for k, rel, want_point in pinocchio_tips(model, data, m, q, base, tip):
        worst_point = max(worst_point, np.abs(np.array([c[k] for c in point]) - want_point).max())
        z, x = np.array([c[k] for c in direction]), np.array([c[k] for c in x_axis])
        got = np.column_stack([x, np.cross(z, x), z])
        worst_angle = max(worst_angle, np.linalg.norm(pin.log3((rel.rotation @ tool).T @ got)))
    assert worst_point < 1e-9, worst_point
    assert worst_angle < 1e-12, worst_angle


def test_tool_reference_values_are_checked(tmp_path):
    path, _ = robot(tmp_path)
    assert "--tool-reference: expected three numbers" in refused(path, "--tool-reference", "1,0")
    for bad in ("0,0,-2", "1e-9,0,1", "1e-13,0,1e-8"):
        assert f"--tool-reference {bad}: must not be (nearly) parallel to the tool direction 0,0,1" \
            in refused(path, "--tool-reference", bad), bad
    for option in ("--tool-reference", "--tool-direction"):
        assert f"{option}: must not be zero" in refused(path, option, "0,0,0")
        assert f"{option}: must not be zero" in refused(path, option, "1e-13,0,0")
        assert f"{option}: a value below 1e-27 that is not 0" in refused(path, option, "1,1e-300,0")
    assert "--tool-point: a value below 1e-27 that is not 0" in refused(path, "--tool-point", "1,1e-300,0")
