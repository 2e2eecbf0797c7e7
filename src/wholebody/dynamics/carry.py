r"""A rigid object carried by the hands, at the torque level: its dynamics in the problem,
the grasps' wrenches as unknowns, and the squeeze between two hands as a force task.

Each hand ``h`` holds the object rigidly (a weld); its wrench ``f_h = (force, torque)`` (N,
N m) is the object's action on the hand, in the hand frame (``LOCAL``) at its origin, and
enters the robot's equations of motion as ``J_h^T f_h`` like a contact's. The object, of
mass ``m`` and rotational inertia ``I`` about its centre of mass (kg m^2, object axes),
obeys Newton-Euler in its frame ``o`` (at its centre of mass):

.. math::

    \mathcal{I}_o A_o + V_o \times^* \mathcal{I}_o V_o
        = F_{gravity} - \sum_h X_{h \leftarrow o}^T f_h

with ``A_o = X_{o <- A} (J_A dv + Jdot_A v)`` its spatial acceleration through the first
hand ``A`` (rigidly attached). A second hand ``B`` moves with the first:
``J_B dv + Jdot_B v - X_{B <- A} (J_A dv + Jdot_A v) = -kp e - kd dV`` (``e``, ``dV``: the
drift of B's pose and velocity relative to A from the grasp's), the closed chain as the
physics holds it.

The **squeeze** of a two-hand grasp is the internal force along the line between the
hands, positive when they press on the object (the same as the physics runs measure):
``s = (n . F_A - n . F_B) / 2`` with ``F_h = -R_h f_h`` the force of hand ``h`` on the object
(world) and ``n`` the unit vector from ``A`` to ``B``. A ``squeeze`` setpoint makes it a
force task (``s = squeeze``) in the grasp's level: without one the internal wrench is left
to the solver's regularisation (none).

With a friction coefficient ``mu``, each hand's force keeps inside the pyramid about the
squeeze axis (the hand presses along ``n`` towards the object, the rest is friction):
``|t_i . F_h| <= mu / sqrt(2) (n_h . F_h)`` for the two tangent directions ``t_i``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from wholebody.errors import ConfigError

__all__ = ["CarriedObject", "GraspRows", "box_inertia"]

LOCAL = pin.ReferenceFrame.LOCAL
GRAVITY = np.array([0.0, 0.0, -9.81])


def box_inertia(mass: float, size: tuple[float, float, float]) -> np.ndarray:
    """The rotational inertia (kg m^2, about the centre, box axes) of a uniform box of
    ``mass`` (kg) and side lengths ``size`` (m)."""
    a, b, c = size
    return mass / 12.0 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])


@dataclass
class GraspRows:
    """One carried object's rows at a state, over ``dv`` (nv) and its hands' wrenches
    (6 per hand, hand frames): ``jacobians`` (one 6 x nv per hand, ``LOCAL``); the object's
    equations of motion ``E_dv dv + E_f f = e`` (6 rows, N and N m); the closure
    ``K dv = k`` (6 rows per hand after the first); the squeeze row ``s . f`` (N); and the
    friction rows ``C f <= 0`` (empty without ``mu``)."""

    jacobians: list[np.ndarray]
    E_dv: np.ndarray
    E_f: np.ndarray
    e: np.ndarray
    K: np.ndarray
    k: np.ndarray
    squeeze: np.ndarray
    C: np.ndarray


@dataclass
class CarriedObject:
    """A rigid object held by ``hands`` (robot frames; the first is the reference of its
    acceleration), module docstring.

    Parameters
    ----------
    name
        Shown in results.
    mass, inertia
        kg; kg m^2 about the centre of mass, in the object's axes (3 x 3).
    hands
        One or two hand frames.
    squeeze
        Setpoint (N) of the squeeze between two hands, or None.
    mu
        Friction coefficient of the grasps, or None (welded: no bound on the wrenches).
    kp, kd
        Gains (1/s^2, 1/s) of the closure's drift correction.
    """

    name: str
    mass: float
    inertia: np.ndarray
    hands: tuple[str, ...]
    squeeze: float | None = None
    mu: float | None = None
    kp: float = 100.0
    kd: float = 20.0
    _offsets: list[pin.SE3] = field(default_factory=list, repr=False)
    _relative: pin.SE3 | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.mass) and self.mass > 0):
            raise ConfigError(f"carried {self.name!r}: mass must be > 0 kg, got {self.mass}")
        self.inertia = np.asarray(self.inertia, dtype=float)
        if self.inertia.shape != (3, 3) or not np.all(np.linalg.eigvalsh(self.inertia) > 0):
            raise ConfigError(f"carried {self.name!r}: inertia must be 3x3 positive definite")
        self.hands = tuple(self.hands)
        if len(self.hands) not in (1, 2):
            raise ConfigError(f"carried {self.name!r}: one or two hands, got {self.hands}")
        if self.squeeze is not None and len(self.hands) != 2:
            raise ConfigError(f"carried {self.name!r}: a squeeze needs two hands")
        if self.mu is not None and (not math.isfinite(self.mu) or self.mu <= 0):
            raise ConfigError(f"carried {self.name!r}: mu must be > 0, got {self.mu}")
        self._spatial = pin.Inertia(self.mass, np.zeros(3), self.inertia)
        self._ids: list[int] = []

    @property
    def size(self) -> int:
        """The number of wrench unknowns: 6 per hand."""
        return 6 * len(self.hands)

    def bind(self, model: pin.Model) -> None:
        """Find the hands' frames in ``model``."""
        for h in self.hands:
            if not model.existFrame(h):
                raise ConfigError(f"carried {self.name!r}: the robot has no frame {h!r}")
        self._ids = [model.getFrameId(h) for h in self.hands]

    def hold(self, data: pin.Data, pose: np.ndarray) -> None:
        """Grasp the object at ``pose`` (4x4, world, at its centre of mass) with the hands
        where ``data`` (after forward kinematics) has them."""
        hands = [data.oMf[i] for i in self._ids]
        obj = pin.SE3(np.asarray(pose, dtype=float))
        self._offsets = [h.actInv(obj) for h in hands]  # object in each hand frame
        self._relative = hands[0].actInv(hands[1]) if len(hands) == 2 else None

    @property
    def held(self) -> bool:
        return bool(self._offsets)

    def rows(self, model: pin.Model, data: pin.Data) -> GraspRows:
        """The rows at the state of ``data`` (forward kinematics with ``(q, v, 0)`` and the
        joint Jacobians)."""
        if not self.held:
            raise ConfigError(f"carried {self.name!r} is not held (call hold())")
        J = [pin.getFrameJacobian(model, data, i, LOCAL) for i in self._ids]
        drift = [pin.getFrameAcceleration(model, data, i, LOCAL) for i in self._ids]
        V = [pin.getFrameVelocity(model, data, i, LOCAL) for i in self._ids]
        X_oA = self._offsets[0].inverse().toActionMatrix()  # hand A's motion -> object's
        Vo = pin.Motion(X_oA @ V[0].vector)
        inertia = self._spatial.matrix()
        E_dv = inertia @ X_oA @ J[0]
        E_f = np.hstack([X.toActionMatrix().T for X in self._offsets])  # X_{h<-o}^T
        pose = data.oMf[self._ids[0]] * self._offsets[0]
        gravity = pin.Force(self.mass * pose.rotation.T @ GRAVITY, np.zeros(3)).vector
        bias = Vo.cross(self._spatial * Vo).vector
        e = gravity - bias - inertia @ X_oA @ drift[0].vector
        K, k = self._closure(data, J, drift, V)
        return GraspRows(J, E_dv, E_f, e, K, k, self._squeeze_row(data), self._friction(data))

    def _closure(self, data, J, drift, V) -> tuple[np.ndarray, np.ndarray]:
        """Hand B's acceleration relative to A's: ``K dv = k`` (module docstring)."""
        if self._relative is None:
            return np.zeros((0, J[0].shape[1])), np.zeros(0)
        oA, oB = data.oMf[self._ids[0]], data.oMf[self._ids[1]]
        X_BA = oB.actInv(oA).toActionMatrix()  # A's motion -> B's
        e = pin.log6(self._relative.actInv(oA.actInv(oB))).vector
        dV = V[1].vector - X_BA @ V[0].vector
        K = J[1] - X_BA @ J[0]
        k = -self.kp * e - self.kd * dV - (drift[1].vector - X_BA @ drift[0].vector)
        return K, k

    def _axis(self, data: pin.Data) -> np.ndarray:
        """The unit vector from hand A to hand B (world)."""
        gap = data.oMf[self._ids[1]].translation - data.oMf[self._ids[0]].translation
        return gap / max(float(np.linalg.norm(gap)), 1e-12)

    def _squeeze_row(self, data: pin.Data) -> np.ndarray:
        """``s . f`` is the squeeze (N): ``(n . F_A - n . F_B) / 2``, ``F_h = -R_h f_h``."""
        row = np.zeros(self.size)
        if len(self.hands) != 2:
            return row
        n = self._axis(data)
        for h, sign in ((0, -0.5), (1, 0.5)):
            R = data.oMf[self._ids[h]].rotation
            row[6 * h : 6 * h + 3] = sign * (R.T @ n)
        return row

    def _friction(self, data: pin.Data) -> np.ndarray:
        """``C f <= 0``: each hand's force on the object inside the pyramid about the axis
        along which it presses (``n`` for A, ``-n`` for B; one hand: no rows)."""
        if self.mu is None or len(self.hands) != 2:
            return np.zeros((0, self.size))
        n = self._axis(data)
        t1 = np.cross(n, [0.0, 0.0, 1.0] if abs(n[2]) < 0.9 else [1.0, 0.0, 0.0])
        t1 /= np.linalg.norm(t1)
        t2 = np.cross(n, t1)
        c = self.mu / math.sqrt(2.0)
        rows = []
        for h, press in ((0, n), (1, -n)):
            R = data.oMf[self._ids[h]].rotation
            for t in (t1, -t1, t2, -t2):  # t . F - c press . F <= 0, F = -R f
                row = np.zeros(self.size)
                row[6 * h : 6 * h + 3] = -(R.T @ (t - c * press))
                rows.append(row)
        return np.array(rows)
