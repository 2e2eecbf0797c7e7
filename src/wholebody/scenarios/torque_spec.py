"""``[torque]`` of a scenario file: what a run with the torque-level backend
(``--backend dynamics``, :mod:`wholebody.dynamics`) adds to the scenario.

.. code-block:: toml

    [torque]
    rate_hz = 1000.0        # control rate (Hz); under MuJoCo a whole number of physics steps
    velocity_gain = 20.0    # K_d (1/s) of the tasks' acceleration form
    com_kp = 5.0            # a floating base: the centre of mass held (x, y) above all (1/s)
    mode = "strict"         # or "weighted"
    acceleration_limits = true  # bound the accelerations by robot.toml [acceleration]
    grasp_mu = 2.0          # friction of a carried object's grasps (none: welded)

    [torque.contacts.left_sole_link]   # a robot frame held in contact
    kind = "patch"          # or "point"
    half_length = 0.1       # m, along the frame's x (patch)
    half_width = 0.05       # m, along its y (patch)
    margin = 0.02           # m, the centre of pressure kept that far inside (patch)
    mu = 0.8                # friction coefficient
    f_min = 5.0             # N, the least normal force
    f_max = 2000.0          # N

    [[torque.pushes]]       # an external force on a robot body, in a physics run
    frame = "torso_2_link"  # the body of this frame is pushed, at its centre of mass
    force = [50.0, 0.0, 0.0]  # N, world axes
    start = 3.5             # s from the run's start
    duration = 0.1          # s
"""

from __future__ import annotations

from dataclasses import dataclass

from wholebody.dynamics.contacts import Contact, PatchContact, PointContact
from wholebody.tomlreader import TomlReader

__all__ = ["ContactSpec", "PushSpec", "TorqueSpec", "parse_torque"]

NON_NEGATIVE = ("f_min", "margin")
"""The contact keys that may be 0 (the others must be positive)."""


@dataclass(frozen=True)
class ContactSpec:
    """``[torque.contacts.FRAME]`` (module docstring)."""

    frame: str
    kind: str = "patch"
    mu: float = 0.8
    f_min: float = 5.0
    f_max: float = 2000.0
    half_length: float = 0.1
    half_width: float = 0.05
    margin: float = 0.0

    def make(self) -> Contact:
        """The contact (:mod:`wholebody.dynamics.contacts`)."""
        if self.kind == "point":
            return PointContact(self.frame, self.mu, self.f_min, self.f_max)
        return PatchContact(
            self.frame,
            self.mu,
            self.f_min,
            self.f_max,
            half_length=self.half_length,
            half_width=self.half_width,
            margin=self.margin,
        )


@dataclass(frozen=True)
class PushSpec:
    """``[[torque.pushes]]``: ``force`` (N, world) on the body of ``frame`` from ``start`` for
    ``duration`` (s)."""

    frame: str
    force: tuple[float, float, float]
    start: float
    duration: float


@dataclass(frozen=True)
class TorqueSpec:
    """``[torque]`` (module docstring)."""

    rate_hz: float = 1000.0
    velocity_gain: float = 20.0
    com_kp: float = 5.0
    mode: str = "strict"
    acceleration_limits: bool = True
    grasp_mu: float | None = None
    contacts: tuple[ContactSpec, ...] = ()
    pushes: tuple[PushSpec, ...] = ()

    @property
    def dt(self) -> float:
        return 1.0 / self.rate_hz


def parse_torque(r: TomlReader, table: dict) -> TorqueSpec:
    """``[torque]`` checked (an empty table: the defaults)."""
    r.only(
        table,
        "torque",
        (
            "rate_hz",
            "velocity_gain",
            "com_kp",
            "mode",
            "acceleration_limits",
            "grasp_mu",
            "contacts",
            "pushes",
        ),
    )
    contacts = tuple(
        _contact(r, frame, c) for frame, c in r.table(table, "contacts", "torque", False).items()
    )
    raw = table.get("pushes", [])
    if not isinstance(raw, list):
        raise r.fail("torque.pushes", "expected [[torque.pushes]] tables")
    com_kp = r.number(table, "com_kp", "torque", default=5.0)
    if com_kp < 0:
        raise r.fail("torque.com_kp", f"expected a rate >= 0 (1/s), got {com_kp}")
    return TorqueSpec(
        rate_hz=r.number(table, "rate_hz", "torque", default=1000.0, positive=True),
        velocity_gain=r.number(table, "velocity_gain", "torque", default=20.0, positive=True),
        com_kp=com_kp,
        mode=r.string(table, "mode", "torque", default="strict", choices=("strict", "weighted")),
        acceleration_limits=r.boolean(table, "acceleration_limits", "torque", default=True),
        grasp_mu=(
            r.number(table, "grasp_mu", "torque", positive=True) if "grasp_mu" in table else None
        ),
        contacts=contacts,
        pushes=tuple(_push(r, p, f"torque.pushes[{i}]") for i, p in enumerate(raw)),
    )


def _contact(r: TomlReader, frame: str, table: object) -> ContactSpec:
    where = f"torque.contacts.{frame}"
    if not isinstance(table, dict):
        raise r.fail(where, "expected a table")
    r.only(table, where, ("kind", "mu", "f_min", "f_max", "half_length", "half_width", "margin"))
    spec = ContactSpec(
        frame,
        r.string(table, "kind", where, default="patch", choices=("patch", "point")),
        *(
            r.number(
                table, k, where, default=getattr(ContactSpec, k), positive=k not in NON_NEGATIVE
            )
            for k in ("mu", "f_min", "f_max", "half_length", "half_width", "margin")
        ),
    )
    if not 0.0 <= spec.f_min <= spec.f_max:
        raise r.fail(where, f"expected 0 <= f_min <= f_max, got {spec.f_min} and {spec.f_max}")
    return spec


def _push(r: TomlReader, table: object, where: str) -> PushSpec:
    if not isinstance(table, dict):
        raise r.fail(where, "expected a table")
    r.only(table, where, ("frame", "force", "start", "duration"))
    start = r.number(table, "start", where)
    if start < 0:
        raise r.fail(f"{where}.start", f"expected a time >= 0 s, got {start}")
    return PushSpec(
        r.string(table, "frame", where),
        r.vector(table, "force", where, 3),  # type: ignore[arg-type]
        start,
        r.number(table, "duration", where, positive=True),
    )
