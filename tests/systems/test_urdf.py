"""The URDF importer (SYSTEMS.md Sec. 4a) without compiling anything: what it refuses (unsafe
or malformed text, robots it cannot simulate), what it makes of a robot (coordinates, merged
bodies by the parallel-axis theorem, kept frames, contacts), the file-argument grammar, the
library's robots, and a round trip: a system file written by hand with the bodies API and the
same robot as URDF give the same M, forces and constraints. Pinocchio's comparisons are in
``tests/systems/test_urdf_pinocchio.py``."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

from biped_opt.system_spec import parse_file_spec
from biped_opt.systems.derive import derive
from biped_opt.systems.description import System, SystemDescriptionError
from biped_opt.systems.files import library_size, load_system
from biped_opt.systems.library.robots import FOLDER, ROBOT_FILES, ROBOTS
from biped_opt.systems.urdf import (
    BASE,
    MAX_BYTES,
    MAX_ELEMENTS,
    UrdfError,
    parse_urdf,
    read_urdf,
    system_from_urdf,
)

HERE = Path(__file__).resolve().parent / "urdf"
GRIPPER = HERE / "gripper.urdf"
HOPPER = HERE / "hopper.urdf"


def _robot(links: str, joints: str = "") -> str:
    return f'<robot name="r">{links}{joints}</robot>'


def _link(name: str, mass: float = 1.0, extra: str = "") -> str:
    return (f'<link name="{name}"><inertial><mass value="{mass}"/><inertia ixx="0.01" '
            f'iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>{extra}</link>')


def _joint(name: str, parent: str, child: str, kind: str = "revolute", extra: str = "") -> str:
    return (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/>'
            f'<child link="{child}"/><axis xyz="0 1 0"/>{extra}</joint>')


TWO = _robot(_link("a") + _link("b"), _joint("j", "a", "b"))


# -- text that is refused before or while parsing ----------------------------------------------

def test_a_billion_laughs_is_refused_before_parsing():
    bomb = ('<?xml version="1.0"?><!DOCTYPE lolz [<!ENTITY lol "lol">'
            + "".join(f'<!ENTITY lol{k + 1} "{"&lol%s;" % (k or "") * 10}">' for k in range(9))
            + ']><robot name="&lol9;"><link name="a"/></robot>')
    with pytest.raises(UrdfError, match="document type declaration or an entity"):
        parse_urdf(bomb)


def test_an_external_entity_is_refused():
    text = ('<!DOCTYPE r [<!ENTITY x SYSTEM "file:///etc/passwd">]>'
            '<robot name="r"><link name="&x;"/></robot>')
    with pytest.raises(UrdfError, match="document type declaration"):
        parse_urdf(text.encode())


def test_size_and_element_bounds(tmp_path):
    with pytest.raises(UrdfError, match=f"longer than {MAX_BYTES}"):
        parse_urdf(" " * (MAX_BYTES + 1))
    with pytest.raises(UrdfError, match=f"more than {MAX_ELEMENTS} elements"):
        parse_urdf(_robot("<a/>" * (MAX_ELEMENTS + 1)))
    big = tmp_path / "big.urdf"
    big.write_bytes(TWO.encode() + b" " * MAX_BYTES)
    with pytest.raises(UrdfError, match="longer than"):
        read_urdf(big)
    with pytest.raises(UrdfError, match="not UTF-8"):
        parse_urdf(b"<robot name='\xff'/>")
    with pytest.raises(UrdfError, match="not well-formed"):
        parse_urdf("<robot><link name='a'></robot>")
    with pytest.raises(UrdfError, match="cannot read"):
        read_urdf(tmp_path / "absent.urdf")


def test_meshes_are_names_never_opened():
    robot = read_urdf(GRIPPER)
    (visual,) = robot.link("base_link").visuals
    assert visual.geometry.kind == "mesh"
    assert visual.geometry.filename == "package://gripper/meshes/base.stl"
    assert visual.geometry.size == (0.001, 0.001, 0.001)
    system_from_urdf(robot)  # (the mesh does not exist: nothing looks for it)


@pytest.mark.parametrize(("text", "message"), [
    ("<model/>", "root element is <model>"),
    (_robot(""), "has no <link>"),
    (_robot(_link("a") + _link("a")), "link 'a' is given twice"),
    (_robot(_link("a") + _link("b"), _joint("j", "a", "c")), "child link 'c' is not a <link>"),
    (_robot(_link("a") + _link("b"), _joint("j", "a", "b", "hinge")), "unknown type 'hinge'"),
    (_robot(_link("a") + _link("b") + _link("c")), "one tree; roots"),
    (_robot(_link("a") + _link("b") + _link("c"),
            _joint("j", "a", "b") + _joint("k", "c", "b")), "already the child of joint 'j'"),
    (_robot(_link("a") + _link("b") + _link("c"),
            _joint("j", "c", "b") + _joint("k", "b", "c")), "not below the root 'a' \\(a cycle\\)"),
    (_robot(_link("a", -1) + _link("b"), _joint("j", "a", "b")), "mass must be >= 0"),
    (_robot(_link("a") + _link("b"), _joint("j", "a", "b", extra='<origin xyz="0 nan 0"/>')),
     "must be finite"),
    (_robot(_link("a") + _link("b"), _joint("j", "a", "b", extra='<origin xyz="0 0"/>')),
     "needs 3 numbers"),
    (_robot(_link("a", extra="<collision><geometry><box size='1 0 1'/></geometry></collision>")),
     "box sizes must be > 0"),
    (_robot(_link("a", extra="<visual><geometry><torus/></geometry></visual>")),
     "unknown geometry <torus>"),
    (_robot(_link("a") + _link("b"), _joint("j", "a", "b", extra="<mimic joint='k'/>")),
     "mimic: no joint 'k'"),
    (_robot(_link("a") + _link("b") + _link("c"),
            _joint("j", "a", "b", extra="<mimic joint='k'/>")
            + _joint("k", "b", "c", extra="<mimic joint='j'/>")), "form a cycle"),
    (_robot(_link("a") + _link("b"), '<joint name="j" type="revolute"><parent link="a"/>'
            '<child link="b"/><axis xyz="0 0 0"/></joint>'), "axis must not be zero"),
    (_robot(_link("a") + _link("b"),
            _joint("j", "a", "b", extra="<limit lower='1' upper='0' effort='1'/>")),
     "lower 1.0 > upper 0.0"),
], ids=lambda v: v[:24] if isinstance(v, str) and not v.startswith("<") else None)
def test_malformed_robots_are_named(text, message):
    with pytest.raises(UrdfError, match=message):
        parse_urdf(text)


# -- robots the importer cannot simulate, and its options -------------------------------------

FINGERS = _robot(_link("a") + _link("b") + _link("c", 0.0) + _link("d", 0.0),
                 _joint("j", "a", "b") + _joint("finger", "b", "c")
                 + _joint("tip", "c", "d", "fixed"))


@pytest.mark.parametrize(("text", "options", "message"), [
    (FINGERS, {}, "joint 'finger' moves only links of zero mass \\(c, d\\): M would be "
                  "singular; lock it \\(lock=finger\\) or all such joints \\(massless=lock\\)"),
    (TWO, {"lock": "arm_*"}, "lock: 'arm_\\*' names no revolute"),
    (TWO, {"contacts": "c"}, "contacts: no link 'c'"),
    (TWO, {"base": "wobbly"}, "option base must be one of floating, fixed"),
    (TWO, {"kp": -1.0}, "option kp must be a number >= 0"),
    (TWO, {"posture": {"k": 0.1}}, "posture: no revolute, continuous or prismatic joint 'k'"),
    (_robot(_link("a") + _link("b"), _joint("j", "a", "b", "planar")),
     {"contacts": "b"}, "a planar joint inside the tree is not supported"),
    (_robot(_link("a") + _link("b"),
            _joint("j", "a", "b", extra="<dynamics friction='0.5'/>")),
     {"contacts": "b"}, "joint 'j' declares Coulomb friction 0.5, which the simulator does not "
                        "model .* friction=ignore"),
    (_robot(_link("a", 0.0) + _link("b"), _joint("j", "a", "b")), {"contacts": "b"},
     "the floating base's links \\(a\\) have no mass"),
    (TWO, {}, "no contacts: the links at the ends of the tree have no collision sphere or box"),
    (_robot(_link("world", 0.0) + _link("a"), _joint("j", "world", "a", "fixed")),
     {"base": "floating"}, "base=floating contradicts the URDF's fixed joint 'j'"),
], ids=lambda v: v[:24] if isinstance(v, str) and not v.startswith("<") else None)
def test_robots_it_cannot_simulate_are_refused_by_name(text, options, message):
    with pytest.raises(UrdfError, match=message):
        system_from_urdf(text, **options)


def test_massless_joints_locked_and_friction_ignored_on_request():
    s = system_from_urdf(FINGERS, contacts="b", massless="lock")
    assert s.coordinate_names == (*BASE, "j") and s.robot.locked == {"finger": 0.0}
    text = _robot(_link("a") + _link("b"), _joint("j", "a", "b", extra="<dynamics friction='1'/>"))
    assert system_from_urdf(text, contacts="b", friction="ignore").coordinate_names[-1] == "j"
    assert system_from_urdf(text, contacts="b", lock="j").coordinate_names == BASE


# -- what the importer makes of a robot --------------------------------------------------------

@pytest.fixture(scope="module")
def gripper() -> System:
    return system_from_urdf(GRIPPER, contacts="base_link+tip")


def test_coordinates_inputs_and_what_the_robot_keeps(gripper):
    s = gripper
    assert s.coordinate_names == (*BASE, "slide", "wrist", "finger_a_joint")
    assert s.u.names() == ("slide_effort", "wrist_effort", "finger_a_joint_effort")
    assert list(s.constraints) == ["base_link_fl", "base_link_fr", "base_link_rl", "base_link_rr",
                                   "tip"]
    imported = s.robot
    assert imported.mimic == {"finger_b_joint": ("finger_a_joint", -1.5, 0.2)}
    assert imported.coordinates == {"slide": "slide", "wrist": "wrist",
                                    "finger_a_joint": "finger_a_joint"}
    assert imported.bodies["tip"] == "finger_a" and imported.bodies["sensor"] == "base_link"
    assert imported.contacts["tip"] == "tip"
    assert imported.robot.joint("wrist").limit.effort == 5.0
    # (no stand: the base's own corners touch, and no joint keeps them still as it goes down)
    assert set(s.problems) == {"drop"} and set(s.maneuvers) == {"drop"}
    assert s.problems["drop"]["decisions"]["wrist_effort"] == (-5.0, 5.0)
    # kp's default: 4 m g h, the base 0.1 above its lowest contact (the box's bottom)
    assert s.defaults == {"g": 9.81, "gamma": 0.0, "drop": 0.05,
                          "kp": pytest.approx(4 * 3.12 * 9.81 * 0.1, rel=1e-15), "kd": 0.0}


def _rpy(r, p, y):
    cr, sr, cp, sp_, cy, sy = (math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y),
                               math.sin(y))
    return (np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
            @ np.array([[cp, 0, sp_], [0, 1, 0], [-sp_, 0, cp]])
            @ np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]]))


def test_a_fixed_link_is_merged_by_the_parallel_axis_theorem(gripper):
    """finger_a carries the tip (0.02 kg at (0.08, 0, 0), its inertia turned by pitch 0.4): one
    body of 0.12 kg, centre and inertia as written out here from the URDF's numbers."""
    body = gripper.bodies["finger_a"]
    parts = [(0.1, np.array([0.04, 0, 0]), np.diag([1e-5, 1e-4, 1e-4])),
             (0.02, np.array([0.08, 0, 0]), _rpy(0, 0.4, 0) @ np.eye(3) * 1e-6
              @ _rpy(0, 0.4, 0).T)]
    mass = sum(m for m, _c, _i in parts)
    centre = sum(m * c for m, c, _i in parts) / mass
    inertia = sum(i + m * ((c - centre) @ (c - centre) * np.eye(3)
                           - np.outer(c - centre, c - centre)) for m, c, i in parts)
    assert float(body.mass) == pytest.approx(mass, rel=1e-15)
    np.testing.assert_allclose(np.array(body.centre, dtype=float), centre, rtol=0, atol=1e-16)
    np.testing.assert_allclose(np.array(body.inertia, dtype=float), inertia, rtol=0, atol=1e-17)
    assert "palm" in gripper.bodies and "tip" not in gripper.bodies


def test_contacts_and_kept_frames_where_the_urdf_puts_them(gripper):
    """The base level at height 1 (every joint at 0, the fingers' mimic offset aside): the
    box's bottom corners at its collision origin -0.05 less half its height, the sensor's frame
    at (0.1, 0, 1.02) turned by yaw pi/2, and the sphere's lowest point its centre less its
    radius (the tip turned by the wrist's origin, then its own pitch)."""
    s = gripper
    q = {c: 0.0 for c in s.q}
    q[s.q[2]] = 1.0
    for name, (sx, sy) in zip(("fl", "fr", "rl", "rr"), ((1, 1), (1, -1), (-1, 1), (-1, -1))):
        at = [float(sp.sympify(v).xreplace(q)) for v in s.contact_points[f"base_link_{name}"][0]]
        assert at == pytest.approx([0.15 * sx, 0.1 * sy, 0.9], abs=1e-15)
        assert float(s.constraints[f"base_link_{name}"].xreplace(q)) == pytest.approx(0.9)
    frame = s.frames["sensor"]
    assert [float(sp.sympify(v).xreplace(q)) for v in frame.position] == pytest.approx(
        [0.1, 0, 1.02], abs=1e-15)
    assert float(sp.sympify(frame.rpy[2]).xreplace(q)) == pytest.approx(math.pi / 2, abs=1e-15)
    tip = [float(sp.sympify(v).xreplace(q)) for v in s.frames["tip"].position]
    turn = _rpy(0.1, -0.2, 0.3) @ _rpy(0, 0.4, 0)
    centre = np.array(tip) + turn @ np.array([0.01, 0, 0])
    assert float(s.constraints["tip"].xreplace(q)) == pytest.approx(centre[2] - 0.01, abs=1e-15)


def test_the_drop_starts_with_its_lowest_contact_drop_above_the_ground():
    s = system_from_urdf(HOPPER)
    n = derive(s).numeric()
    for value in (-0.1, 0.0, 0.07):
        y0, mode = n.initial_state("drop", value)
        heights = n.constraints(y0[:8])
        assert mode == 0 and heights.min() == pytest.approx(0.05, abs=1e-15)
        assert y0[3] == value and y0[4] == value / 2  # (roll s, pitch s / 2)


def test_stand_starts_on_its_contacts_with_their_velocities_zero():
    """solo12's stand: the four feet on the ground, the base going down at s and the hinges
    turning so that the feet stay (Da q' = 0 to rounding)."""
    s = load_system("solo12")
    n = derive(s).numeric()
    y0, mode = n.initial_state("stand", 0.3)
    assert mode == 15 and y0[18 + 2] == -0.3
    np.testing.assert_allclose(n.constraints(y0[:18]), 0, atol=1e-15)
    np.testing.assert_allclose(n.constraint_jacobian(y0[:18]) @ y0[18:], 0, atol=1e-15)


def test_fixed_base_and_the_world_link():
    fixed = system_from_urdf(HOPPER, base="fixed")
    assert fixed.coordinate_names == ("left_hip", "right_hip")
    assert list(fixed.maneuvers) == ["swing"] and fixed.robot.base == "fixed"
    text = HOPPER.read_text().replace(
        '<link name="body">', '<link name="world"/><joint name="anchor" type="floating">'
        '<parent link="world"/><child link="body"/></joint><link name="body">')
    floating = system_from_urdf(text)
    assert floating.coordinate_names == (*BASE, "left_hip", "right_hip")


# -- file arguments, the Python API, the library -----------------------------------------------

def test_file_arguments_give_the_importer_its_options(tmp_path):
    spec = parse_file_spec("r.urdf:base=fixed,contacts=a+b,lock=arm_*+head_1")
    assert spec.arguments == (("base", "fixed"), ("contacts", "a+b"), ("lock", "arm_*+head_1"))
    path = tmp_path / "hopper.urdf"
    path.write_text(HOPPER.read_text())
    s = load_system(f"{path}:base=fixed,contacts=left_foot,lock=right_hip")
    assert s.coordinate_names == ("left_hip",) and list(s.constraints) == ["left_foot"]
    assert s.reads == (path.resolve(),) and s.source.endswith(":base=fixed,contacts=left_foot,"
                                                             "lock=right_hip")
    assert load_system(str(path)).coordinate_names == (*BASE, "left_hip", "right_hip")
    with pytest.raises(SystemDescriptionError, match="unknown option mass \\(options: base, "):
        load_system(f"{path}:mass=2")
    with pytest.raises(SystemDescriptionError, match="no such system file"):
        load_system(str(tmp_path / "absent.urdf"))


def test_system_from_urdf_takes_text_and_system_from_urdf_is_the_class_method():
    a = System.from_urdf(HOPPER.read_text(), name="hop")
    b = system_from_urdf(HOPPER)
    assert a.name == "hop" and b.name == "hopper"
    assert a.coordinate_names == b.coordinate_names


def test_library_robots_by_name_with_their_sizes_and_licences():
    for name in ROBOTS:
        s = load_system(name)
        assert library_size(name) == (len(s.constraints), len(s.q)), name
        folder = ROBOT_FILES[name].parent
        assert {p.name for p in folder.iterdir()} == {
            ROBOT_FILES[name].name, "LICENSE", "LICENSE.example-robot-data", "README.md"}, name
    g1 = load_system("g1")
    assert len(g1.constraints) == 8 and "left_elbow_joint" in g1.robot.locked
    assert all(c.split("_")[0] in ("left", "right") for c in g1.coordinate_names[6:])
    assert all("ankle" in c for c in g1.constraints)
    assert sorted(p.name for p in FOLDER.iterdir()) == ["bolt", "g1", "solo12"]


# -- a round trip: the hopper written by hand and the hopper from its URDF ---------------------

def test_the_hopper_by_hand_and_from_its_urdf_agree():
    """``urdf/hopper_by_hand.py`` writes the hopper with the bodies API from its URDF's numbers;
    at random states both give the same M, forces (efforts and the posture hold included),
    constraints and Jacobian, to 1e-13 of each quantity's size (two derivations of one
    robot: the same sums in other orders)."""
    by_hand = derive(load_system(str(HERE / "hopper_by_hand.py"))).numeric()
    imported = derive(system_from_urdf(HOPPER)).numeric()
    rng = np.random.default_rng(3)
    for _ in range(5):
        q, dq, u = rng.uniform(-1, 1, 8), rng.uniform(-2, 2, 8), rng.uniform(-1, 1, 2)
        for f in ("mass_matrix", "constraints", "constraint_jacobian"):
            want = getattr(by_hand, f)(q)
            np.testing.assert_allclose(getattr(imported, f)(q), want, rtol=0,
                                       atol=1e-13 * np.abs(want).max(), err_msg=f)
        want = by_hand.forces(q, dq, u, 0)
        np.testing.assert_allclose(imported.forces(q, dq, u, 0), want, rtol=0,
                                   atol=1e-13 * np.abs(want).max())
        want = by_hand.constraint_jacobian_rate(q, dq)
        np.testing.assert_allclose(imported.constraint_jacobian_rate(q, dq), want, rtol=0,
                                   atol=1e-13 * np.abs(want).max())


def test_a_continuous_joint_is_a_revolute_one_without_limits():
    """The hopper's hips as continuous joints: the same coordinates and dynamics, the limits
    dropped (the efforts' bounds stay)."""
    text = HOPPER.read_text().replace('type="revolute"', 'type="continuous"')
    continuous = system_from_urdf(text)
    assert continuous.robot.robot.joint("left_hip").limit.lower is None
    assert continuous.problems["drop"]["decisions"]["left_hip_effort"] == (-4.0, 4.0)
    a, b = derive(continuous).numeric(), derive(system_from_urdf(HOPPER)).numeric()
    q = np.random.default_rng(4).uniform(-1, 1, 8)
    assert np.array_equal(a.mass_matrix(q), b.mass_matrix(q))
