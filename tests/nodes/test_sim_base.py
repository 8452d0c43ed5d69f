"""The base's pose and twist as the Simulation Interfaces give them (biped_opt.nodes.sim_control),
against SciPy's rotations: an independent reference for the roll-pitch-yaw convention of URDF
(R = Rz(yaw) Ry(pitch) Rx(roll)) and for the angular velocity of a rotating frame."""

from __future__ import annotations

import types

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from biped_opt.nodes.sim_control import (
    FLOATING,
    PLANAR,
    Refused,
    base_pose,
    name_filter,
    set_base,
)

COORDS = (*FLOATING, "hip", "knee")


def _state(rng):
    q = rng.uniform(-1.0, 1.0, len(COORDS))
    q[4] = rng.uniform(-1.2, 1.2)  # (pitch away from +-90 degrees)
    return np.concatenate([q, rng.uniform(-2.0, 2.0, len(COORDS))])


def _msg(**fields):
    return types.SimpleNamespace(**{k: types.SimpleNamespace(**v) for k, v in fields.items()})


@pytest.mark.parametrize("seed", range(5))
def test_floating_base_pose_and_twist_agree_with_scipy(seed):
    rng = np.random.default_rng(seed)
    y = _state(rng)
    d = len(COORDS)
    pos, quat, lin, ang = base_pose(COORDS, y)
    rpy = y[3:6]
    reference = Rotation.from_euler("xyz", rpy)  # (extrinsic x, y, z: Rz Ry Rx)
    assert np.allclose(reference.as_matrix(), Rotation.from_quat(quat).as_matrix(), atol=1e-14)
    assert pos == tuple(y[:3]) and lin == tuple(y[d:d + 3])
    # omega from the rotation a short time on: R(t + h) R(t)^T = exp([omega] h)
    h = 1e-6
    ahead = Rotation.from_euler("xyz", rpy + h * y[d + 3:d + 6])
    ahead_back = Rotation.from_euler("xyz", rpy - h * y[d + 3:d + 6])
    omega = (ahead * ahead_back.inv()).as_rotvec() / (2 * h)
    assert np.allclose(ang, omega, atol=1e-8)  # (central difference: error ~ h^2)


@pytest.mark.parametrize("seed", range(5))
def test_setting_what_was_got_gives_the_state_back(seed):
    rng = np.random.default_rng(seed)
    y = _state(rng)
    pos, quat, lin, ang = base_pose(COORDS, y)
    pose = _msg(position=dict(zip("xyz", pos)), orientation=dict(zip("xyzw", quat)))
    twist = _msg(linear=dict(zip("xyz", lin)), angular=dict(zip("xyz", ang)))
    other = y.copy()
    other[:6] = 0.0
    other[len(COORDS):len(COORDS) + 6] = 0.0
    back = set_base(COORDS, other, pose, twist)
    assert np.allclose(back, y, atol=1e-12)


def test_planar_base_refuses_what_leaves_the_plane():
    coords = (*PLANAR, "x1")
    y = np.array([0.1, 0.9, 0.2, 0.5, 0.0, 0.0, -1.0, 0.0])
    pos, quat, lin, ang = base_pose(coords, y)
    # (velocities x' = 0, z' = 0, th' = -1: the angular velocity about y is -th')
    assert pos == (0.1, 0.0, 0.9) and lin == (0.0, 0.0, 0.0) and ang == (0.0, 1.0, 0.0)
    # the base frame has pitch -th (SYSTEMS.md Sec. 6)
    assert np.allclose(Rotation.from_quat(quat).as_euler("xyz"), [0.0, -0.2, 0.0])
    tilted = _msg(position=dict(x=0.0, y=0.0, z=1.0), orientation=dict(x=0.1, y=0.0, z=0.0,
                                                                        w=np.sqrt(0.99)))
    with pytest.raises(Refused, match="rotation about y"):
        set_base(coords, y, tilted)
    with pytest.raises(Refused, match="unit quaternion"):
        set_base(coords, y, _msg(position=dict(x=0.0, y=0.0, z=1.0),
                                 orientation=dict(x=0.0, y=0.0, z=0.0, w=0.0)))
    with pytest.raises(Refused, match="no base"):
        base_pose(("a", "b"), np.zeros(4))


@pytest.mark.parametrize(("text", "safe"), [
    ("biped", True), ("^walker.*", True), ("a.*b.*c$", True), ("a.*b.*c.*d", False),
    ("(a+)+$", False), ("a|b", False), ("[a-z]", False), ("a{2}", False), ("x" * 257, False)])
def test_only_a_safe_subset_of_regular_expressions_is_matched(text, safe):
    assert (name_filter(text) is not None) == safe
