r"""Contacts at the torque level: where the robot touches the world, the wrench it may take
there, and the acceleration that keeps the contact held.

A **patch contact** (:class:`PatchContact`: a foot's sole, a hand's grasp) holds a frame of
the robot fixed. Its wrench ``f = (f_x, f_y, f_z, tau_x, tau_y, tau_z)`` (N, N m) is the
world's action on the robot, expressed in the contact frame (Pinocchio's ``LOCAL``) at the
frame's origin, which is the centre of a rectangular patch of half-length ``half_length``
along the frame's x and half-width ``half_width`` along its y; z is the patch's normal,
pointing into the robot. It enters the equations of motion as ``J_c^T f`` with ``J_c`` the
frame's ``LOCAL`` Jacobian (6 x nv). Every step it must satisfy (linear rows on ``f``):

* unilateral: ``f_min <= f_z <= f_max``;
* friction pyramid, inscribed in the cone of coefficient ``mu``:
  ``|f_x| <= mu f_z / sqrt(2)``, ``|f_y| <= mu f_z / sqrt(2)``;
* centre of pressure inside the patch, ``margin`` from its edges:
  ``|tau_y| <= (half_length - margin) f_z``, ``|tau_x| <= (half_width - margin) f_z``
  (``CoP = (-tau_y, tau_x) / f_z`` in the patch);
* yaw friction: ``|tau_z| <= mu min(half_length, half_width) f_z`` (a conservative bound,
  on the patch less its margin).

A **point contact** (:class:`PointContact`: a fingertip, a foot's corner) holds a point of
the robot. Its force ``f = (f_x, f_y, f_z)`` (N) is in the world's axes at the frame's origin
(``LOCAL_WORLD_ALIGNED``), with the unilateral and pyramid rows about the unit ``normal``
(world, into the robot; default up).

Both hold their frame with the acceleration ``J_c dv + Jdot_c v = -kp e - kd V`` (``e``, the
drift from the pose or point the contact was made at, ``V`` the frame's velocity; ``kp``
1/s^2, ``kd`` 1/s): with ``kp = kd = 0`` the frame's acceleration is zero, and the gains only
pull back a drift that integration or a simulator's compliance let in. The kernels of
:mod:`wholebody.kernels.contacts` compute these rows (``Jdot_c v`` by the same forward
difference as the stack's rows, :mod:`wholebody.dynamics.solver`); a contact gives them its
kind, frame, gains and reference (:meth:`Contact.pack`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from wholebody.errors import ConfigError
from wholebody.kernels.contacts import CP_KD, CP_KP, CP_REF

__all__ = ["Contact", "PatchContact", "PointContact"]


def _frozen(arrays: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
    """``arrays`` made read-only (a contact's constant rows, shared by every step)."""
    for a in arrays:
        a.setflags(write=False)
    return arrays


def _positive(name: str, value: float, what: str, strict: bool = True) -> float:
    value = float(value)
    if not math.isfinite(value) or value < 0.0 or (strict and value == 0.0):
        rule = "positive" if strict else "non-negative"
        raise ConfigError(f"contact {name!r}: {what} must be a finite {rule} number, got {value}")
    return value


@dataclass
class Contact:
    """What every contact has (see the module docstring for the wrench's frame and units).

    Parameters
    ----------
    frame
        The robot frame held (a name of the Pinocchio model's frames).
    mu
        Friction coefficient (dimensionless).
    f_min, f_max
        Bounds of the normal force (N): ``f_min > 0`` keeps the contact loaded.
    kp, kd
        Drift correction gains (1/s^2, 1/s).
    """

    frame: str
    mu: float = 0.5
    f_min: float = 0.0
    f_max: float = 1e4
    kp: float = 0.0
    kd: float = 0.0
    reference: np.ndarray | None = field(default=None, repr=False)
    """Where the contact was made (set by :meth:`make`): a 4x4 pose (patch) or a point."""
    wrench_target: np.ndarray | None = field(default=None, repr=False)
    """A force task on the contact's wrench (:meth:`set_wrench_target`), or None."""

    size = 0
    """The wrench's dimension."""

    def __post_init__(self) -> None:
        self.mu = _positive(self.frame, self.mu, "mu")
        self.f_min = _positive(self.frame, self.f_min, "f_min", strict=False)
        self.f_max = _positive(self.frame, self.f_max, "f_max")
        if self.f_min > self.f_max:
            raise ConfigError(
                f"contact {self.frame!r}: f_min ({self.f_min} N) exceeds f_max ({self.f_max} N)"
            )
        self.kp = _positive(self.frame, self.kp, "kp", strict=False)
        self.kd = _positive(self.frame, self.kd, "kd", strict=False)
        self._id = -1

    def set_wrench_target(self, wrench: np.ndarray | None) -> None:
        """Ask for this wrench (the contact's frame and units: N, N m; ``size`` entries; NaN
        leaves an entry free) in a level of its own right below the contacts', above every
        task: a hand pressing on a table with a given force. None removes the task."""
        if wrench is None:
            self.wrench_target = None
            return
        w = np.asarray(wrench, dtype=float)
        if w.shape != (self.size,) or np.isinf(w).any():
            raise ConfigError(
                f"contact {self.frame!r}: a wrench target is {self.size} finite numbers or "
                f"NaN, got {wrench!r}"
            )
        self.wrench_target = w

    def bind(self, model: pin.Model) -> None:
        """Find the frame in ``model`` (a clear error if it has none by that name)."""
        if not model.existFrame(self.frame):
            raise ConfigError(f"contact: the robot has no frame {self.frame!r}")
        self._id = model.getFrameId(self.frame)

    def make(self, model: pin.Model, data: pin.Data) -> None:
        """Hold the frame where it is now (``data`` after forward kinematics)."""
        raise NotImplementedError

    @property
    def frame_id(self) -> int:
        """The frame's index in the model it was bound to (-1 before :meth:`bind`)."""
        return self._id

    @property
    def wrench_bounds(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(C, lower, upper)``: the wrench's rows ``lower <= C f <= upper`` (N, N m;
        read-only)."""
        return self._wrench

    def pack(self, out: np.ndarray) -> None:
        """The gains and the reference into ``out``, a row of the kernels' ``par``
        (:mod:`wholebody.kernels.contacts`); a ConfigError if the contact was never made."""
        if self.reference is None:
            raise ConfigError(f"contact {self.frame!r} was never made (call make())")
        out[CP_KP], out[CP_KD] = self.kp, self.kd
        ref = self.reference.ravel()
        out[CP_REF : CP_REF + ref.size] = ref

    def quiet(self) -> np.ndarray:
        """The rows ``R`` (r x size) of the wrench that the last level keeps small when
        nothing above decides them (``R f -> 0``, N): the tangential forces, and for a patch
        the torques over its smaller half-size, so that the centre of pressure stays central
        and the load moves between contacts rather than to their edges."""
        raise NotImplementedError

    def _pyramid(self, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Unilateral and friction rows on the first three entries of an ``n``-wrench whose
        normal force is its third: ``f_min <= f_z <= f_max``, ``|f_t| - mu f_z / sqrt 2 <= 0``."""
        c = self.mu / math.sqrt(2.0)
        C = np.zeros((5, n))
        C[0, 2] = 1.0
        for i, (t, sign) in enumerate(((0, 1.0), (0, -1.0), (1, 1.0), (1, -1.0))):
            C[1 + i, t], C[1 + i, 2] = sign, -c
        lower = np.r_[self.f_min, np.full(4, -np.inf)]
        upper = np.r_[self.f_max, np.zeros(4)]
        return C, lower, upper


@dataclass
class PatchContact(Contact):
    """A 6-D contact on a rectangular patch centred at the frame's origin, normal along the
    frame's z (a sole, a flat grasp); the wrench in the frame (``LOCAL``), module docstring.

    ``half_length`` (m, along the frame's x) and ``half_width`` (m, along y): the patch;
    ``margin`` (m): the centre of pressure is kept that far inside its edges (a sole rolls
    onto its edge before the CoP reaches it: its contact is soft, its edge rounded)."""

    half_length: float = 0.1
    half_width: float = 0.05
    margin: float = 0.0

    size = 6

    def __post_init__(self) -> None:
        super().__post_init__()
        self.half_length = _positive(self.frame, self.half_length, "half_length")
        self.half_width = _positive(self.frame, self.half_width, "half_width")
        self.margin = _positive(self.frame, self.margin, "margin", strict=False)
        if self.margin >= min(self.half_length, self.half_width):
            raise ConfigError(
                f"contact {self.frame!r}: margin {self.margin} m leaves no patch of "
                f"{self.half_length} m x {self.half_width} m"
            )
        self._wrench = _frozen(self.wrench_rows())

    def make(self, model: pin.Model, data: pin.Data) -> None:
        self.reference = data.oMf[self._id].homogeneous.copy()

    def wrench_rows(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``C``, ``lower``, ``upper`` of the module docstring's rows on the wrench (made
        anew: the contact's own copy is read-only)."""
        C, lower, upper = self._pyramid(6)
        extra = np.zeros((6, 6))
        hl, hw = self.half_length - self.margin, self.half_width - self.margin
        yaw = self.mu * min(hl, hw)
        for i, (axis, arm) in enumerate(((4, hl), (3, hw), (5, yaw))):
            extra[2 * i, axis], extra[2 * i, 2] = 1.0, -arm  # tau <= arm f_z
            extra[2 * i + 1, axis], extra[2 * i + 1, 2] = -1.0, -arm  # -tau <= arm f_z
        return (
            np.vstack([C, extra]),
            np.r_[lower, np.full(6, -np.inf)],
            np.r_[upper, np.zeros(6)],
        )

    def quiet(self) -> np.ndarray:
        # the torques over the patch's smaller half-size: a centre of pressure at its edge
        # weighs as much as the whole normal force moved sideways
        R = np.eye(6)[[0, 1, 3, 4, 5]]
        R[2:] /= min(self.half_length, self.half_width)
        return R

    def cop(self, wrench: np.ndarray) -> np.ndarray:
        """The centre of pressure (m, in the patch's x-y) of a wrench of this contact."""
        return np.array([-wrench[4], wrench[3]]) / wrench[2]

    def cop_margin(self, wrench: np.ndarray) -> float:
        """The distance (m) from the centre of pressure to the patch's nearest edge (negative
        outside; at least ``margin`` while the wrench is in its bounds)."""
        x, y = self.cop(wrench)
        return float(min(self.half_length - abs(x), self.half_width - abs(y)))


@dataclass
class PointContact(Contact):
    """A point contact at the frame's origin; its force in the world's axes, friction about
    ``normal`` (world, unit, pointing into the robot)."""

    normal: tuple[float, float, float] = (0.0, 0.0, 1.0)

    size = 3

    def __post_init__(self) -> None:
        super().__post_init__()
        n = np.asarray(self.normal, dtype=float)
        norm = float(np.linalg.norm(n)) if n.shape == (3,) else math.nan
        if not math.isfinite(norm) or norm < 1e-9:
            raise ConfigError(f"contact {self.frame!r}: normal must be a 3-vector, got {n}")
        n = n / norm
        # a right-handed basis (t1, t2, n): the pyramid's rows are in it
        t1 = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
        t1 /= np.linalg.norm(t1)
        self._basis = np.array([t1, np.cross(n, t1), n])
        C, lower, upper = self._pyramid(3)
        self._wrench = _frozen((C @ self._basis, lower, upper))

    def make(self, model: pin.Model, data: pin.Data) -> None:
        self.reference = data.oMf[self._id].translation.copy()

    def quiet(self) -> np.ndarray:
        return self._basis[:2].copy()
