"""An independent reference for robots imported from URDF: Pinocchio's rigid-body algorithms
(its own URDF parser, CRBA, RNEA, frame Jacobians and classical accelerations) in the importer's
coordinates, and the event rules of ``tests/simulation/user/reference_rigid.py`` (SciPy's DOP853
at rtol 1e-12) on top. Imports nothing from biped_opt.

Coordinates. Pinocchio's model gets a root joint that is a composite of a translation and three
hinges about z, y and x (so its configuration is (x, y, z, yaw, pitch, roll) and its velocity
their rates, R = Rz(yaw) Ry(pitch) Rx(roll)); the importer's floating base is (x, y, z, roll,
pitch, yaw) with the same R, followed by the joints. Both orders are matched by name through
``coordinates`` (the importer's names: ``base_x`` ... ``base_yaw``, then the joints). Joints the
importer locks are locked here with Pinocchio's ``buildReducedModel``. A mimic joint is a
linear map: Pinocchio's model keeps it as a joint of its own, and q_full = T q + c (its column
of T the multiplier in its leader's column, c the offset), so that M = T^T M_full T and the
forces T^T f_full (the Lagrangian of the full model restricted to the map).

The forces besides the bodies' (what the importer declares as applied forces): each joint
coordinate's effort u_k, its damping -c_k q_k' (Pinocchio's ``model.damping``, read from the
URDF; a follower's c_f m^2 on its leader) and the posture hold kp (q0_k - q_k) - kd q_k'.

Contacts: points given as (link, point in the link's frame, radius): the height of the point
minus the radius (a sphere's lowest point), its row of Da the z row of the point's Jacobian in
world axes, and (d/dt Da) q' the z component of its classical acceleration at q'' = 0.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from tests.simulation.user import reference_rigid

BASE = ("base_x", "base_y", "base_z", "base_roll", "base_pitch", "base_yaw")
#: the composite root joint's coordinates in its order, by the importer's names
ROOT_ORDER = ("base_x", "base_y", "base_z", "base_yaw", "base_pitch", "base_roll")


def root_joint() -> pin.JointModelComposite:
    root = pin.JointModelComposite(pin.JointModelTranslation())
    for hinge in (pin.JointModelRZ(), pin.JointModelRY(), pin.JointModelRX()):
        root.addJoint(hinge)
    return root


class PinocchioRobot(reference_rigid.Model):
    """A robot of Pinocchio's in the importer's coordinates (see the module docstring)."""

    def __init__(self, urdf: str, coordinates: list[str], *, floating: bool = True,
                 contacts: list[tuple[str, tuple[float, float, float], float]] = (),
                 locked: dict[str, float] | None = None,
                 mimic: dict[str, tuple[str, float, float]] | None = None,
                 posture: dict[str, float] | None = None, kp: float = 0.0, kd: float = 0.0,
                 g: float = 9.81, gamma: float = 0.0) -> None:
        full = (pin.buildModelFromUrdf(urdf, root_joint()) if floating
                else pin.buildModelFromUrdf(urdf))
        locked = dict(locked or {})
        if locked:
            q_ref = pin.neutral(full)
            for name, value in locked.items():
                joint = full.joints[full.getJointId(name)]
                q_ref[joint.idx_q] = value
            ids = [full.getJointId(name) for name in locked]
            full = pin.buildReducedModel(full, ids, q_ref)
        full.gravity.linear[:] = (0.0, 0.0, -g)
        self.model = full
        self.data = full.createData()
        self.coordinates = list(coordinates)
        self.nq = self.nv = len(coordinates)
        self.n = len(contacts)
        self.gamma = gamma
        self.kp, self.kd = kp, kd
        self.mimic = dict(mimic or {})
        posture = dict(posture or {})
        # T: the full model's velocity from ours; c: its configuration's offset
        nv = full.nv
        self.T = np.zeros((nv, self.nv))
        self.c = np.zeros(nv)
        index = {name: k for k, name in enumerate(coordinates)}
        if floating:
            for k, name in enumerate(ROOT_ORDER):
                self.T[k, index[name]] = 1.0
        self.joint_columns = []  # (our column, damping) of each leader joint
        for jid in range(1, full.njoints):
            name = full.names[jid]
            if name == "root_joint":
                continue
            joint = full.joints[jid]
            assert joint.nq == joint.nv == 1, f"{name}: only one-coordinate joints here"
            row = joint.idx_v
            if name in self.mimic:
                leader, mult, offset = self.mimic[name]
                self.T[row, index[leader]] = mult
                self.c[row] = offset
            else:
                self.T[row, index[name]] = 1.0
                self.joint_columns.append((index[name], name))
        self.damping = self.T.T @ np.diag(full.damping) @ self.T
        self.rest = np.zeros(self.nv)
        self.held = np.zeros(self.nv)  # 1 on the joint coordinates the posture hold acts on
        for column, name in self.joint_columns:
            self.rest[column] = posture.get(name, 0.0)
            self.held[column] = 1.0
        self.u = np.zeros(self.nv)
        # a frame at each contact point (a sphere's centre)
        self.frames = []
        self.radius = np.array([r for _l, _p, r in contacts], dtype=float)
        for k, (link, point, _radius) in enumerate(contacts):
            body = full.frames[full.getFrameId(link)]
            placement = body.placement * pin.SE3(np.eye(3), np.array(point, dtype=float))
            frame = pin.Frame(f"contact_{k}", body.parentJoint, placement,
                              pin.FrameType.OP_FRAME)
            self.frames.append(full.addFrame(frame))
        self.data = full.createData()

    # -- the configuration of the full model
    def full(self, q: np.ndarray, v: np.ndarray | None = None):
        qf = self.T @ q + self.c
        return qf, (None if v is None else self.T @ v)

    def set_efforts(self, u: dict[str, float]) -> None:
        """Efforts on the joints by name (the others 0)."""
        self.u = np.zeros(self.nv)
        for column, name in self.joint_columns:
            self.u[column] = u.get(name, 0.0)

    # -- Eq. (1) in our coordinates
    def mass(self, y):
        qf, _ = self.full(y[:self.nq])
        M = pin.crba(self.model, self.data, qf)
        M = np.triu(M) + np.triu(M, 1).T
        return self.T.T @ M @ self.T

    def bias(self, y):
        """The bodies' generalised force: -(velocity products + weight)."""
        qf, vf = self.full(y[:self.nq], y[self.nq:])
        return -self.T.T @ pin.rnea(self.model, self.data, qf, vf, np.zeros(self.model.nv))

    def applied(self, y):
        q, v = y[:self.nq], y[self.nq:]
        return (self.u - self.damping @ v
                + self.held * (self.kp * (self.rest - q) - self.kd * v))

    def force(self, y, contact):
        return self.bias(y) + self.applied(y)

    def pos_rate(self, y):
        return y[self.nq:]

    def _kinematics(self, y, velocity=True):
        qf, vf = self.full(y[:self.nq], y[self.nq:])
        if velocity:
            pin.forwardKinematics(self.model, self.data, qf, vf, np.zeros(self.model.nv))
        else:
            pin.forwardKinematics(self.model, self.data, qf)
        pin.updateFramePlacements(self.model, self.data)
        return qf

    def heights(self, y):
        self._kinematics(y, velocity=False)
        return np.array([self.data.oMf[f].translation[2] for f in self.frames]) - self.radius

    def points(self, y):
        self._kinematics(y, velocity=False)
        return np.array([self.data.oMf[f].translation for f in self.frames])

    def jac(self, y):
        qf = self._kinematics(y, velocity=False)
        pin.computeJointJacobians(self.model, self.data, qf)
        rows = [pin.getFrameJacobian(self.model, self.data, f,
                                     pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[2]
                for f in self.frames]
        return np.array(rows).reshape(self.n, self.model.nv) @ self.T

    def drift(self, y):
        self._kinematics(y)
        return np.array([pin.getFrameClassicalAcceleration(
            self.model, self.data, f, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED).linear[2]
            for f in self.frames])

    def _chol(self, y):  # (M depends on q: never cached)
        return np.linalg.inv(np.linalg.cholesky(self.mass(y)))

    # -- what the comparisons need
    def accelerations(self, y, mode):
        """(q'', reactions) in the contact set ``mode`` (indices), the reactions the
        least-squares ones (unique for independent rows)."""
        return self.accel(y, frozenset(mode))

    def impact_velocity(self, y, mode):
        return self.impact(y, frozenset(mode))[self.nq:]

    def energy(self, y) -> float:
        qf, vf = self.full(y[:self.nq], y[self.nq:])
        kinetic = 0.5 * float(vf @ self.mass_full(qf) @ vf)
        return kinetic + float(pin.computePotentialEnergy(self.model, self.data, qf))

    def mass_full(self, qf):
        M = pin.crba(self.model, self.data, qf)
        return np.triu(M) + np.triu(M, 1).T


def drop(robot: PinocchioRobot, y0, *, t_end: float = 2.0, max_events: int = 40,
         band: float = reference_rigid.BAND) -> reference_rigid.Run:
    """The importer's ``drop`` maneuver, simulated by the reference: from y0 in the air to the
    base's lowest point (z' rises through 0) after the first touchdown."""
    nq = robot.nq
    z_rate = nq + robot.coordinates.index("base_z")
    terminal = reference_rigid.Terminal(guard=lambda y: -y[z_rate], after_touchdown=True)
    return reference_rigid.simulate(robot, np.asarray(y0, dtype=float), (), terminal=terminal,
                                    band=band, t_end=t_end, max_events=max_events)


def relative_error(ours, theirs) -> float:
    """max |ours - theirs| / max(max |theirs|, tiny)."""
    ours, theirs = np.asarray(ours, dtype=float), np.asarray(theirs, dtype=float)
    scale = max(float(np.abs(theirs).max(initial=0.0)), math.ulp(1.0))
    return float(np.abs(ours - theirs).max(initial=0.0)) / scale
