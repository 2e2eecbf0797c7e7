"""Scenario files: an experiment as data (TOML), checked key by key.

A scenario names the robot, the backend, the control rate, the stack (the paper's preset and
its weights), the hands (frame tasks and their gains), the planner (a DMP learned from a
demonstration), the objects in the world (props and obstacles) and a list of phases, each
with one planner per hand. Layout (every key is checked; unknown keys are errors)::

    format = 2                         # required, first: the format this file is written
                                       # for (wholebody.formats; 2: start defaults to home)

    [scenario]
    name = "coordinated_carry"         # required
    title = "..."                      # optional, for plots and reports
    paper = "Sec. 5.3, Figs. 15-17"    # optional, where the paper describes it
    robot = "mobile_humanoid"          # bundled name or path (relative to this file)
    backend = "projection"             # projection | pinv | hqp
    rate_hz = 100.0
    start = "home"                     # the robot's posture at the start: "home" (its
                                       # robot.toml [home], the default), "neutral" (all
                                       # joints at 0) or a table of joint positions (rad, m;
                                       # joints not named at home), the base at the origin:
                                       # start = { left_elbow_flexion = 0.8 }

    [stack]                            # the paper's H (see wholebody.presets)
    energy = 0.5                       # w1 on each arm's f_p
    limits_arms = 0.05                 # w2 on the arms' joints
    limits_waist = 30.0                # w2 on the other joints
    manipulability = 0.0               # w3
    gain = 1.0                         # k
    wheel_metric = 0.01                # velocity metric of the wheels
    waist_metric = 1.0                 # velocity metric of the waist's joints (100: dear)
    stiffness = "learned"              # "learned" (the robot's model) or a number (N m/rad)
    acceleration = true                # the robot's acceleration limits as a hard box
    spring = "paper"                   # the arm energy's spring: "paper" (1/2 k (pi - |alpha|)^2),
                                       # "signed" (1/2 k (pi - alpha)^2) or "none"
    human_arm_angle = 0.0              # weight of the pull towards the human arm angle in H
    human_arm_angle_kp = 0.0           # rate (1/s) of the human arm angle as a task level

    [hands.right]                      # any number of hands
    frame = "right_tool"
    kp = 20.0                          # 1/s
    ki = 5.0                           # 1/s^2

    [planner]                          # DMP used by phases with planner = "dmp"
    demo = "demos/reach_demo.npz"      # positions (N, 3) and times (N,), relative to this file
    n_basis = 50
    stiffness = 1050.0                 # K; damping D = 2 sqrt(K)

    [[objects]]                        # drawn in MeshCat and in the plots
    name = "shelf"
    kind = "box"                       # box | cylinder | sphere
    size = [0.4, 1.6, 0.03]            # box: edge lengths (m)
    radius = 0.04                      # cylinder, sphere (m)
    height = 0.2                       # cylinder (m, along z)
    position = [1.72, 0.0, 0.42]       # centre (m, world)
    obstacle = false                   # true: phases may avoid it
    margin = 0.0                       # m added around it for avoidance
    mass = 2.0                         # kg, physics runs only: a free body of uniform
                                       # density (without: fixed in the world)
    note = "..."                       # optional provenance / decisions

    [collision]                        # optional: wholebody.tasks.CollisionAvoidance
    enforce = true                     # false: only measure the closest distance
    obstacles = ["shelf"]              # fixed objects the links keep off (not carried ones:
                                       # those are attached to their hand while carried)
    self_collision = true              # links against links too
    safety = 0.01                      # m, d_s
    influence = 0.05                   # m, d_i
    speed = 0.5                        # m/s allowed at d_i

    [torque]                           # optional: the torque-level backend (--backend
                                       # dynamics): rate, contacts, pushes
                                       # (wholebody.scenarios.torque_spec)

    [[phases]]
    name = "reach"
    duration = 5.0                     # s
    closed_chain = false               # hold the hands' relative pose (dual-arm carry)
    primary = "right"                  # closed chain: the task is b = secondary in a = primary
    squeeze_n = 10.0                   # closed chain carrying: the squeeze (N) on the object
                                       # (--backend dynamics)
    [phases.hands.right]
    planner = "dmp"                    # dmp | min_jerk | hold | follow | free
    goal = [1.701, -0.45675, 0.46133]  # m, world (dmp, min_jerk)
    rotate = [0.0, -1.5708, 0.0]       # rad, world rotation vector applied to the start
                                       # pose to give the goal orientation (dmp, min_jerk)
    avoid = ["cylinder_1"]             # obstacles (dmp)
    shape = "demo"                     # dmp: "demo" (goal-shift generalisation of the
                                       # demonstration), "aligned" (the demonstration
                                       # carried onto this motion's chord, then fitted) or
                                       # "straight" (fitted to a minimum-jerk straight line)
    carry = "panel"                    # an object moving rigidly with this hand in the phase
    [phases.hands.left]
    planner = "follow"                 # the primary's motion through the grasp transforms

``free``: the hand has no task in the phase (the objectives keep the arm relaxed); its next
reference starts where it actually is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wholebody.errors import ConfigError
from wholebody.formats import FORMAT_KEY, SCENARIO, check_format
from wholebody.presets import SPRINGS, PaperWeights
from wholebody.scenarios.torque_spec import TorqueSpec, parse_torque
from wholebody.tomlreader import TomlReader, config_error, load_toml

__all__ = [
    "BACKENDS",
    "CollisionSpec",
    "HandPhase",
    "HandSpec",
    "ObjectSpec",
    "PhaseSpec",
    "PlannerSpec",
    "ScenarioSpec",
    "StackSpec",
    "load_scenario",
    "parse_scenario",
]

BACKENDS = ("projection", "pinv", "hqp", "dynamics")
PLANNERS = ("dmp", "min_jerk", "hold", "follow", "free")
KINDS = ("box", "cylinder", "sphere")


@dataclass(frozen=True)
class StackSpec(PaperWeights):
    """The paper's weights (:class:`~wholebody.presets.PaperWeights`) and the spring's
    stiffness: a constant (N m/rad) or ``"learned"`` (the robot's stiffness network)."""

    stiffness: float | str = "learned"
    acceleration: bool = True


@dataclass(frozen=True)
class HandSpec:
    name: str
    frame: str
    kp: float = 20.0
    ki: float = 5.0


@dataclass(frozen=True)
class PlannerSpec:
    demo: Path | None = None
    n_basis: int = 50
    stiffness: float = 1050.0


@dataclass(frozen=True)
class ObjectSpec:
    name: str
    kind: str
    position: tuple[float, float, float]
    size: tuple[float, float, float] = (0.0, 0.0, 0.0)
    radius: float = 0.0
    height: float = 0.0
    obstacle: bool = False
    margin: float = 0.0
    note: str = ""
    mass: float | None = None
    """kg, for physics runs: a free body of uniform density (None: fixed in the world)."""

    @property
    def pose(self) -> np.ndarray:
        """Its pose where the scenario puts it (4x4, world): at its position, the world's
        axes."""
        T = np.eye(4)
        T[:3, 3] = self.position
        return T


@dataclass(frozen=True)
class HandPhase:
    planner: str
    goal: tuple[float, float, float] | None = None
    rotate: tuple[float, float, float] = (0.0, 0.0, 0.0)
    avoid: tuple[str, ...] = ()
    carry: str | None = None
    shape: str = "demo"


@dataclass(frozen=True)
class PhaseSpec:
    name: str
    duration: float
    hands: dict[str, HandPhase]
    closed_chain: bool = False
    primary: str | None = None
    squeeze_n: float | None = None
    """The squeeze (N) the torque level holds on the carried object (``--backend dynamics``;
    the velocity backends cannot set a force)."""


START_POSTURES = ("home", "neutral")


@dataclass(frozen=True)
class CollisionSpec:
    """``[collision]``: keep the robot's links apart and off the listed objects
    (:class:`~wholebody.tasks.CollisionAvoidance` in a level above every task when
    ``enforce``; the closest distance is measured either way). Distances in m, ``speed`` in
    m/s."""

    enforce: bool = True
    self_collision: bool = True
    safety: float = 0.01
    influence: float = 0.05
    speed: float = 0.5
    obstacles: tuple[str, ...] = ()


@dataclass(frozen=True)
class ScenarioSpec:
    path: Path
    name: str
    robot: str
    backend: str
    rate_hz: float
    stack: StackSpec
    hands: dict[str, HandSpec]
    planner: PlannerSpec
    objects: dict[str, ObjectSpec]
    phases: tuple[PhaseSpec, ...]
    title: str = ""
    paper: str = ""
    extra: dict[str, Any] = field(default_factory=dict)
    collision: CollisionSpec | None = None
    """``[collision]``, if the file has one."""
    torque: TorqueSpec = field(default_factory=TorqueSpec)
    """``[torque]``: the torque-level backend's rate, contacts and pushes."""
    start: str | dict[str, float] = "home"
    """The start posture: ``"home"``, ``"neutral"`` or joint positions by name (rad, m; the
    joints and their limits are checked against the robot when it is loaded)."""

    @property
    def dt(self) -> float:
        return 1.0 / self.rate_hz

    @property
    def duration(self) -> float:
        return sum(p.duration for p in self.phases)

    def error(self, key: str, message: str) -> ConfigError:
        return config_error(self.path, key, message)


def _rotation_vector(r: TomlReader, spec: dict, where: str) -> tuple[float, float, float]:
    """``rotate`` (rad): a rotation vector of angle at most pi (a larger one is degrees)."""
    rotate = r.vector(spec, "rotate", where, 3, (0.0, 0.0, 0.0))
    angle = math.sqrt(sum(v * v for v in rotate))
    if angle > math.pi + 1e-6:
        raise r.fail(
            f"{where}.rotate",
            f"a rotation vector in radians has an angle of at most "
            f"pi; this one's is {angle:g} (degrees? {angle:g} deg = "
            f"{math.radians(angle):.4f} rad)",
        )
    return rotate  # type: ignore[return-value]


def load_scenario(path: str | Path) -> ScenarioSpec:
    """Read and check a scenario file (see the module docstring for the layout).

    Raises
    ------
    ConfigError
        Naming the file, the key and what was expected.
    """
    path = Path(path)
    return parse_scenario(load_toml(path, "scenario"), path)


def parse_scenario(data: dict, path: str | Path) -> ScenarioSpec:
    """Check a scenario's content (a parsed TOML document) as :func:`load_scenario` checks a
    file; ``path`` names it in errors and resolves its relative paths (a sweep's cases are
    their scenario file with keys changed)."""
    path = Path(path)
    r = TomlReader(path)
    check_format(r, data, SCENARIO)
    r.only(
        data,
        "",
        (
            FORMAT_KEY,
            "scenario",
            "stack",
            "hands",
            "planner",
            "objects",
            "phases",
            "collision",
            "torque",
        ),
    )

    head = r.table(data, "scenario", "", required=True)
    r.only(head, "scenario", ("name", "title", "paper", "robot", "backend", "rate_hz", "start"))
    name = r.string(head, "name", "scenario")
    robot = r.string(head, "robot", "scenario", default="mobile_humanoid")
    backend = r.string(head, "backend", "scenario", default="projection", choices=BACKENDS)
    rate = r.number(head, "rate_hz", "scenario", default=100.0, positive=True)

    stack = _stack(r, r.table(data, "stack", "", required=False))
    hands = _hands(r, r.table(data, "hands", "", required=True))
    planner = _planner(r, path, r.table(data, "planner", "", required=False))
    objects = _objects(r, data.get("objects", []))

    raw_phases = data.get("phases")
    if not isinstance(raw_phases, list) or not raw_phases:
        raise r.fail("phases", "expected at least one [[phases]] table")
    phases = []
    seen: set[str] = set()
    for i, table in enumerate(raw_phases):
        phases.append(_phase(r, table, f"phases[{i}]", hands, objects, planner, seen))
    collision = None
    if "collision" in data:
        collision = _collision(
            r, r.table(data, "collision", "", required=True), objects, phases, rate
        )
    return ScenarioSpec(
        torque=parse_torque(r, r.table(data, "torque", "", required=False)),
        collision=collision,
        path=path,
        name=name,
        robot=robot,
        backend=backend,
        rate_hz=rate,
        stack=stack,
        hands=hands,
        planner=planner,
        objects=objects,
        phases=tuple(phases),
        title=r.string(head, "title", "scenario", ""),
        paper=r.string(head, "paper", "scenario", ""),
        start=_start(r, head),
    )


def _collision(
    r: TomlReader, table: dict, objects: dict[str, ObjectSpec], phases: list[PhaseSpec], rate: float
) -> CollisionSpec:
    """``[collision]``: the constraint's distances and speed, and the objects it keeps the
    robot from (static ones: a carried object moves with the hands)."""
    r.only(table, "collision", tuple(CollisionSpec.__dataclass_fields__))
    spec = CollisionSpec(
        enforce=r.boolean(table, "enforce", "collision", default=True),
        self_collision=r.boolean(table, "self_collision", "collision", default=True),
        safety=r.number(table, "safety", "collision", default=0.01),
        influence=r.number(table, "influence", "collision", default=0.05, positive=True),
        speed=r.number(table, "speed", "collision", default=0.5, positive=True),
        obstacles=r.names(table, "obstacles", "collision") if "obstacles" in table else (),
    )
    if not 0 <= spec.safety < spec.influence:
        raise r.fail(
            "collision.safety",
            f"expected 0 <= safety < influence ({spec.influence} m), got {spec.safety}",
        )
    if spec.speed / rate > spec.influence - spec.safety:
        raise r.fail(
            "collision.speed",
            f"speed / rate_hz = {spec.speed / rate:.3g} m exceeds "
            f"influence - safety = {spec.influence - spec.safety:.3g} m: a step "
            "could cross the safety distance",
        )
    carried = {hp.carry for p in phases for hp in p.hands.values() if hp.carry}
    for name in spec.obstacles:
        if name not in objects:
            raise r.fail(
                "collision.obstacles",
                f"unknown object {name!r}; objects: {', '.join(objects) or '(none)'}",
            )
        if name in carried:
            raise r.fail(
                "collision.obstacles",
                f"{name!r} is carried: it moves with the hands, so it cannot be a fixed obstacle",
            )
    return spec


def _stack(r: TomlReader, st: dict) -> StackSpec:
    """``[stack]``: the paper's weights, the stiffness and the acceleration switch."""
    r.only(st, "stack", tuple(StackSpec.__dataclass_fields__))
    stiffness: float | str = "learned"
    if "stiffness" in st and st["stiffness"] != "learned":
        stiffness = r.number(st, "stiffness", "stack")
        if stiffness < 0:
            raise r.fail("stack.stiffness", 'expected "learned" or a number >= 0 N m/rad')
    stack = StackSpec(
        **{
            k: r.number(st, k, "stack", default=getattr(StackSpec, k))
            for k in ("energy", "limits_arms", "limits_waist", "manipulability", "gain")
        },
        wheel_metric=r.number(st, "wheel_metric", "stack", default=0.01, positive=True),
        waist_metric=r.number(st, "waist_metric", "stack", default=1.0, positive=True),
        stiffness=stiffness,
        acceleration=r.boolean(st, "acceleration", "stack", default=True),
        spring=r.string(st, "spring", "stack", default="paper", choices=SPRINGS),
        human_arm_angle=r.number(st, "human_arm_angle", "stack", default=0.0),
        human_arm_angle_kp=r.number(st, "human_arm_angle_kp", "stack", default=0.0),
    )
    if stack.human_arm_angle < 0:
        raise r.fail("stack.human_arm_angle", "expected a weight >= 0")
    if stack.human_arm_angle_kp < 0:
        raise r.fail("stack.human_arm_angle_kp", "expected a rate >= 0 (1/s)")
    if stack.gain < 0:
        raise r.fail("stack.gain", f"expected a number >= 0, got {stack.gain}")
    return stack


def _hands(r: TomlReader, tables: dict) -> dict[str, HandSpec]:
    """``[hands.NAME]``: a frame and the PI gains of each hand, at least one."""
    hands: dict[str, HandSpec] = {}
    for hname, table in tables.items():
        where = f"hands.{hname}"
        if not isinstance(table, dict):
            raise r.fail(where, "expected a table")
        r.only(table, where, ("frame", "kp", "ki"))
        kp = r.number(table, "kp", where, default=20.0)
        ki = r.number(table, "ki", where, default=5.0)
        if kp < 0 or ki < 0:
            raise r.fail(where, "kp and ki must be >= 0")
        hands[hname] = HandSpec(hname, r.string(table, "frame", where), kp, ki)
    if not hands:
        raise r.fail("hands", "expected at least one hand")
    return hands


def _planner(r: TomlReader, path: Path, pl: dict) -> PlannerSpec:
    """``[planner]``: the DMP's demonstration (relative to the file) and settings."""
    r.only(pl, "planner", ("demo", "n_basis", "stiffness"))
    demo = None
    if "demo" in pl:
        demo = path.parent / r.string(pl, "demo", "planner")
        if not demo.is_file():
            raise r.fail("planner.demo", f"file {demo} does not exist")
    n_basis = r.number(pl, "n_basis", "planner", default=50, positive=True)
    if n_basis != int(n_basis):
        raise r.fail("planner.n_basis", f"expected an integer, got {n_basis}")
    return PlannerSpec(
        demo, int(n_basis), r.number(pl, "stiffness", "planner", default=1050.0, positive=True)
    )


def _objects(r: TomlReader, raw: Any) -> dict[str, ObjectSpec]:
    """``[[objects]]``: boxes, cylinders and spheres, each named once."""
    if not isinstance(raw, list):
        raise r.fail("objects", "expected an array of tables ([[objects]])")
    objects: dict[str, ObjectSpec] = {}
    for i, table in enumerate(raw):
        obj = _object(r, table, f"objects[{i}]")
        if obj.name in objects:
            raise r.fail(f"objects[{i}].name", f"object {obj.name!r} is defined twice")
        objects[obj.name] = obj
    return objects


def _object(r: TomlReader, table: Any, where: str) -> ObjectSpec:
    if not isinstance(table, dict):
        raise r.fail(where, "expected a table")
    keys = (
        "name",
        "kind",
        "size",
        "radius",
        "height",
        "position",
        "obstacle",
        "margin",
        "note",
        "mass",
    )
    r.only(table, where, keys)
    kind = r.string(table, "kind", where, choices=KINDS)
    obj = ObjectSpec(
        name=r.string(table, "name", where),
        kind=kind,
        position=r.vector(table, "position", where, 3),  # type: ignore[arg-type]
        size=r.vector(table, "size", where, 3) if kind == "box" else (0.0, 0.0, 0.0),  # type: ignore[arg-type]
        radius=r.number(table, "radius", where, positive=True) if kind != "box" else 0.0,
        height=r.number(table, "height", where, positive=True) if kind == "cylinder" else 0.0,
        obstacle=r.boolean(table, "obstacle", where, default=False),
        margin=r.number(table, "margin", where, default=0.0),
        note=r.string(table, "note", where, default=""),
        mass=r.number(table, "mass", where, positive=True) if "mass" in table else None,
    )
    if kind == "box" and min(obj.size) <= 0:
        raise r.fail(f"{where}.size", f"box edges must be > 0 m, got {list(obj.size)}")
    if obj.margin < 0:
        raise r.fail(f"{where}.margin", "expected a number >= 0 m")
    return obj


def _start(r: TomlReader, head: dict) -> str | dict[str, float]:
    """``[scenario] start``: ``"home"`` (default), ``"neutral"`` or a table of joint positions
    (finite numbers, rad or m); whether the joints exist and are within their limits is
    checked against the robot (:func:`wholebody.scenarios.runner.start_configuration`)."""
    value = head.get("start", "home")
    if isinstance(value, str):
        return r.string(head, "start", "scenario", default="home", choices=START_POSTURES)
    if not isinstance(value, dict):
        raise r.fail(
            "scenario.start",
            f'expected "home", "neutral" or a table of joint positions (rad, m), got {value!r}',
        )
    return {joint: r.number(value, joint, "scenario.start") for joint in value}


def _phase(
    r: TomlReader,
    table: Any,
    where: str,
    hands: dict[str, HandSpec],
    objects: dict[str, ObjectSpec],
    planner: PlannerSpec,
    seen: set[str],
) -> PhaseSpec:
    if not isinstance(table, dict):
        raise r.fail(where, "expected a table")
    r.only(table, where, ("name", "duration", "closed_chain", "primary", "hands", "squeeze_n"))
    name = r.string(table, "name", where)
    if name in seen:
        raise r.fail(f"{where}.name", f"phase {name!r} is defined twice")
    seen.add(name)
    duration = r.number(table, "duration", where, positive=True)
    closed = r.boolean(table, "closed_chain", where, default=False)
    primary = r.string(table, "primary", where, default="") or None
    hp = r.table(table, "hands", where, required=True)
    out = {
        hname: _hand_phase(r, spec, f"{where}.hands.{hname}", hname, hands, objects, planner)
        for hname, spec in hp.items()
    }
    _check_phase_hands(r, where, out, hands, closed, primary)
    squeeze = None
    if "squeeze_n" in table:
        squeeze = r.number(table, "squeeze_n", where)
        if not (closed and any(h.carry for h in out.values())):
            raise r.fail(f"{where}.squeeze_n", "a squeeze needs a closed chain carrying an object")
    return PhaseSpec(name, duration, out, closed, primary, squeeze)


def _hand_phase(
    r: TomlReader,
    spec: Any,
    w: str,
    hname: str,
    hands: dict[str, HandSpec],
    objects: dict[str, ObjectSpec],
    planner: PlannerSpec,
) -> HandPhase:
    """One hand's planner in a phase (``[phases.hands.NAME]``)."""
    if hname not in hands:
        raise r.fail(w, f"unknown hand {hname!r}; the [hands] are {', '.join(hands)}")
    if not isinstance(spec, dict):
        raise r.fail(w, "expected a table")
    r.only(spec, w, ("planner", "goal", "rotate", "avoid", "carry", "shape"))
    kind = r.string(spec, "planner", w, choices=PLANNERS)
    moves = kind in ("dmp", "min_jerk")
    for key in ("goal", "rotate"):
        if not moves and key in spec:
            raise r.fail(f"{w}.{key}", f"planner {kind!r} takes no {key}")
    goal = r.vector(spec, "goal", w, 3) if moves else None
    if kind == "dmp" and planner.demo is None:
        raise r.fail(f"{w}.planner", 'planner "dmp" needs [planner] demo = a demonstration')
    avoid = r.names(spec, "avoid", w) if "avoid" in spec else ()
    for a in avoid:
        if a not in objects or not objects[a].obstacle:
            raise r.fail(f"{w}.avoid", f"{a!r} is not an object with obstacle = true")
    if avoid and kind != "dmp":
        raise r.fail(f"{w}.avoid", "only the dmp planner avoids obstacles")
    carry = r.string(spec, "carry", w, default="") or None
    if carry is not None and carry not in objects:
        raise r.fail(f"{w}.carry", f"unknown object {carry!r}")
    shape = r.string(spec, "shape", w, default="demo", choices=("demo", "aligned", "straight"))
    if shape != "demo" and kind != "dmp":
        raise r.fail(f"{w}.shape", "only the dmp planner has a shape")
    return HandPhase(kind, goal, _rotation_vector(r, spec, w), avoid, carry, shape)  # type: ignore[arg-type]


def _check_phase_hands(
    r: TomlReader,
    where: str,
    out: dict[str, HandPhase],
    hands: dict[str, HandSpec],
    closed: bool,
    primary: str | None,
) -> None:
    """Every hand planned; a closed chain or a follower has a primary with its own planner;
    at least one hand has a task."""
    missing = [h for h in hands if h not in out]
    if missing:
        raise r.fail(f"{where}.hands", f"no planner for hand(s) {', '.join(missing)}")
    follow = [h for h, s in out.items() if s.planner == "follow"]
    if closed and len(hands) != 2:
        raise r.fail(f"{where}.closed_chain", f"needs two hands, the scenario has {len(hands)}")
    if follow or closed:
        if primary is None or primary not in hands:
            raise r.fail(
                f"{where}.primary",
                'a phase with planner "follow" or closed_chain '
                f"needs primary = one of {', '.join(hands)}",
            )
        if out[primary].planner in ("follow", "free"):
            raise r.fail(
                f"{where}.hands.{primary}",
                "the primary hand needs a planner of its own (dmp, min_jerk or hold)",
            )
    if all(s.planner == "free" for s in out.values()):
        raise r.fail(f"{where}.hands", 'at least one hand needs a task (not all "free")')
