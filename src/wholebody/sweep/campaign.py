"""Campaign files: a base scenario (or a built-in campaign) and the axes to vary.

A campaign is a TOML file, checked like a scenario file (unknown keys are errors naming the
file and the key)::

    format = 1                       # required, first: the format this file is written for
                                     # (wholebody.formats)

    [campaign]
    name = "carry_gains"
    scenario = "coordinated_carry"   # a scenario file (relative to this file) or a bundled
                                     # name; or builtin = "random_targets" (below)
    samples = 4                      # random draws per grid point (default 1)
    seed = 0                         # the draws' seed (default 0)
    duration_scale = 1.0             # every phase's duration times this (default 1)
    objective = "tracking_error_max_m"   # the metric the best cases minimise
    sim = "kinematic"                # or "mujoco" (physics; the sim extra)

    [[axes]]                         # a grid axis: every value
    key = "stack.energy"             # any scenario key, dotted; phases and objects by name:
    values = [0.0, 0.5, 1.0]         # "phases.carry.hands.right.goal", "objects.panel.mass"

    [[axes]]                         # a random axis: one draw per sample
    key = "hands.right.kp"
    uniform = [10.0, 40.0]           # or log_uniform = [lo, hi], or choice = [a, b, ...]

Besides the scenario's keys, an axis may vary ``backend`` (projection, pinv, hqp),
``engine`` (the hierarchical QP's QP engine), ``sim`` and ``robot``
(``scenario.backend`` and ``scenario.robot`` are the same keys).

The cases are the grid's product times ``samples`` draws, numbered in a fixed order; draw
``k``'s random values come from a generator seeded with ``(seed, k)``, the same at every grid
point (grid points are compared on the same draws), so a case is the same whatever runs it
and in whatever order. Every axis value is checked before anything runs: a
case's scenario is the base scenario with its keys set, read by the scenario reader.

``builtin = "random_targets"`` needs ``robot`` (a robot name or directory) and ``samples``:
case ``i`` drives the robot's first arm's tool from the home posture to the pose it has at
a configuration drawn uniformly within the joint limits (so that it is reachable), a
minimum-jerk reach of ``duration`` s (default 3), the other hands free.
"""

from __future__ import annotations

import copy
import functools
import hashlib
import itertools
import json
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wholebody.errors import ConfigError
from wholebody.formats import CAMPAIGN, FORMAT_KEY, SCENARIO, check_format
from wholebody.scenarios.spec import BACKENDS, ScenarioSpec, parse_scenario
from wholebody.tomlreader import TomlReader, load_toml

__all__ = ["Axis", "Campaign", "Case", "load_campaign"]

ALIASES = {"backend": "scenario.backend", "robot": "scenario.robot"}
"""Axis keys that name a scenario key too (varying both is an error)."""
SIMS = ("kinematic", "mujoco")
BUILTINS = ("random_targets",)


@dataclass(frozen=True)
class Axis:
    """One varied key: its grid ``values``, or a random ``kind`` (``uniform``,
    ``log_uniform``, ``choice``) with its ``bounds`` or choices."""

    key: str
    values: tuple = ()
    kind: str = "grid"
    bounds: tuple = ()

    def draw(self, rng: np.random.Generator) -> Any:
        """One random value."""
        if self.kind == "uniform":
            return float(rng.uniform(*self.bounds))
        if self.kind == "log_uniform":
            lo, hi = (math.log(b) for b in self.bounds)
            return float(math.exp(rng.uniform(lo, hi)))
        return self.bounds[int(rng.integers(len(self.bounds)))]


@dataclass(frozen=True)
class Case:
    """One run of a campaign: its number and the values of the varied keys."""

    index: int
    values: dict[str, Any] = field(default_factory=dict)
    sample: int = 0
    """Its draw within its grid point: cases of one draw share their random values (and
    random target), so that grid points are compared on the same draws."""

    @property
    def name(self) -> str:
        """``case_00012``."""
        return f"case_{self.index:05d}"


@dataclass(frozen=True)
class Campaign:
    """A parsed campaign file (module docstring)."""

    path: Path
    name: str
    scenario: dict[str, Any]
    """The base scenario's content (TOML as a dict)."""
    scenario_path: Path
    axes: tuple[Axis, ...]
    samples: int = 1
    seed: int = 0
    duration_scale: float = 1.0
    objective: str = "tracking_error_max_m"
    sim: str = "kinematic"
    builtin: str | None = None
    builtin_options: dict[str, Any] = field(default_factory=dict)
    bundled: bool = False
    """The base scenario is one of the package's (resolved where a case runs)."""

    def cases(self) -> list[Case]:
        """Every case, in order (module docstring)."""
        grid = [a for a in self.axes if a.kind == "grid"]
        random = [a for a in self.axes if a.kind != "grid"]
        combos = list(itertools.product(*(a.values for a in grid))) or [()]
        out = []
        for point in combos:
            for sample in range(self.samples):
                rng = np.random.default_rng([self.seed, sample])
                values = {a.key: v for a, v in zip(grid, point, strict=True)}
                values.update({a.key: a.draw(rng) for a in random})
                out.append(Case(len(out), values, sample))
        return out

    def fingerprint(self) -> str:
        """A hash of everything that decides the cases' results, not the campaign's name or
        objective (a sweep's directory holds one campaign: resuming it with another is
        refused; renamed or ranked by another metric, it is the same), nor the scenario's
        format number (always the current one: a sweep started before the files carried it
        resumes once the key is added)."""
        described = {k: v for k, v in self.describe().items() if k not in ("name", "objective")}
        described["scenario"] = {k: v for k, v in self.scenario.items() if k != FORMAT_KEY}
        text = json.dumps(described, sort_keys=True, default=str)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def describe(self) -> dict[str, Any]:
        """The campaign as plain data (``campaign.json`` in a sweep's directory)."""
        return {
            "name": self.name,
            "scenario": self.scenario,
            "builtin": self.builtin,
            "builtin_options": self.builtin_options,
            "samples": self.samples,
            "seed": self.seed,
            "duration_scale": self.duration_scale,
            "sim": self.sim,
            "objective": self.objective,
            "axes": [
                {"key": a.key, "kind": a.kind, "values": list(a.values), "bounds": list(a.bounds)}
                for a in self.axes
            ],
        }

    def case_spec(self, case: Case) -> tuple[ScenarioSpec, dict[str, Any]]:
        """The scenario of a case and its run options (``backend``, ``engine``, ``sim``)."""
        data = copy.deepcopy(self.scenario)
        if self.builtin is not None:
            data = random_target_scenario(self, case.sample)
        options: dict[str, Any] = {"sim": self.sim}
        for key, value in case.values.items():
            if key in ("backend", "engine", "sim"):
                options[key] = value
            else:
                set_key(data, "scenario.robot" if key == "robot" else key, value)
        path = self.scenario_path
        if self.bundled:  # found where this process has the package (a cluster's node)
            from wholebody.resources import tasks_dir

            path = tasks_dir() / path.name
        where = path.with_name(f"{path.stem}[{case.name}].toml")
        return parse_scenario(data, where), options


def set_key(data: dict[str, Any], key: str, value: Any) -> None:
    """Set a dotted key of a scenario document: ``phases.NAME`` and ``objects.NAME`` pick
    the array entry of that name, a number the entry at that index (``...goal.2``: a goal's
    z). A :class:`ConfigError` for a path that does not exist."""
    parts = key.split(".")
    node: Any = data
    for i, part in enumerate(parts[:-1]):
        node = _child(node, part, key, ".".join(parts[:i]), create=i == 0)
    last = parts[-1]
    if isinstance(node, list):
        if not last.isdigit() or int(last) >= len(node):
            raise ConfigError(
                f"axis {key!r}: {'.'.join(parts[:-1])} has {len(node)} entries; "
                f"{last!r} is not one of their indices"
            )
        node[int(last)] = value
    elif isinstance(node, dict):
        node[last] = value
    else:
        raise ConfigError(f"axis {key!r}: {'.'.join(parts[:-1])} is a value, not a table")


def _child(node: Any, part: str, key: str, where: str, create: bool) -> Any:
    """The entry ``part`` of a table or array on the way along ``key``."""
    if isinstance(node, list):
        if part.isdigit() and int(part) < len(node):
            return node[int(part)]
        match = [e for e in node if isinstance(e, dict) and e.get("name") == part]
        if not match:
            names = [e.get("name") for e in node if isinstance(e, dict)]
            raise ConfigError(f"axis {key!r}: no entry named {part!r} in {where} (it has {names})")
        return match[0]
    if isinstance(node, dict):
        child = node.setdefault(part, {}) if create else node.get(part)
        if child is None:
            raise ConfigError(
                f"axis {key!r}: the scenario has no {where + '.' if where else ''}{part}"
            )
        return child
    raise ConfigError(f"axis {key!r}: {where} is a value, not a table")


def load_campaign(path: str | Path) -> Campaign:
    """Read and check a campaign file; every axis value is tried on the base scenario.

    Raises
    ------
    ConfigError
        Naming the file, the key and what was expected.
    """
    path = Path(path).resolve()  # cases may run in other processes, elsewhere
    r = TomlReader(path)
    data = load_toml(path, "campaign")
    check_format(r, data, CAMPAIGN)
    r.only(data, "", (FORMAT_KEY, "campaign", "axes"))
    head = r.table(data, "campaign", "", required=True)
    r.only(
        head,
        "campaign",
        (
            "name",
            "scenario",
            "builtin",
            "robot",
            "duration",
            "samples",
            "seed",
            "duration_scale",
            "objective",
            "sim",
        ),
    )
    samples = _count(r, head, "samples", 1)
    seed = _count(r, head, "seed", 0, minimum=0)
    builtin, options, scenario, scenario_path = _base(r, path, head)
    campaign = Campaign(
        path=path,
        name=r.string(head, "name", "campaign", default=path.stem),
        scenario=scenario,
        scenario_path=scenario_path,
        axes=tuple(_axes(r, data.get("axes", []))),
        samples=samples,
        seed=seed,
        duration_scale=r.number(head, "duration_scale", "campaign", default=1.0, positive=True),
        objective=r.string(head, "objective", "campaign", default="tracking_error_max_m"),
        sim=r.string(head, "sim", "campaign", default="kinematic", choices=SIMS),
        builtin=builtin,
        builtin_options=options,
        bundled=_is_bundled(scenario_path),
    )
    _check_axes(r, campaign)
    _check_values(r, campaign)
    return campaign


def _is_bundled(path: Path) -> bool:
    from wholebody.resources import tasks_dir

    return path.resolve().parent == tasks_dir().resolve()


def _check_axes(r: TomlReader, campaign: Campaign) -> None:
    """Axes that cannot be meant: the same key twice under two names, a robot axis on a
    built-in campaign (its robot makes the targets), repeated grid values, and several
    samples with nothing random to draw."""
    keys = [ALIASES.get(a.key, a.key) for a in campaign.axes]
    for key in set(keys):
        if keys.count(key) > 1:
            raise r.fail(
                "axes",
                f"{key} is varied by two axes (backend and robot are "
                "scenario.backend and scenario.robot)",
            )
    if campaign.builtin is not None and "scenario.robot" in keys:
        raise r.fail("axes", "a built-in campaign's robot is [campaign] robot, not an axis")
    for i, axis in enumerate(campaign.axes):
        plain = [json.dumps(v, sort_keys=True) for v in axis.values]
        if len(set(plain)) != len(plain):
            raise r.fail(f"axes[{i}].values", "a value is repeated")
    if (
        campaign.samples > 1
        and all(a.kind == "grid" for a in campaign.axes)
        and campaign.builtin is None
    ):
        raise r.fail(
            "campaign.samples", "several samples but no random axis: they would be the same run"
        )


def _count(r: TomlReader, head: dict, key: str, default: int, minimum: int = 1) -> int:
    value = head.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise r.fail(f"campaign.{key}", f"expected a whole number >= {minimum}, got {value!r}")
    return value


def _base(r: TomlReader, path: Path, head: dict) -> tuple[str | None, dict, dict, Path]:
    """The base scenario (its content and path) or the built-in campaign and its options."""
    if ("scenario" in head) == ("builtin" in head):
        raise r.fail(
            "campaign", f'expected either scenario = "FILE or NAME" or builtin = "{BUILTINS[0]}"'
        )
    if "builtin" in head:
        builtin = r.string(head, "builtin", "campaign", choices=BUILTINS)
        if "robot" not in head:
            raise r.fail("campaign.robot", f"builtin {builtin!r} needs robot = NAME or DIR")
        options = {
            "robot": r.string(head, "robot", "campaign"),
            "duration": r.number(head, "duration", "campaign", default=3.0, positive=True),
        }
        return builtin, options, {}, path.with_name(f"{builtin}.toml")
    for key in ("robot", "duration"):
        if key in head:
            raise r.fail(
                f"campaign.{key}",
                "only for a builtin campaign (a scenario file names its robot and durations)",
            )
    scenario_path = _scenario_file(r, path, r.string(head, "scenario", "campaign"))
    return None, {}, load_toml(scenario_path, "scenario"), scenario_path


def _scenario_file(r: TomlReader, path: Path, name: str) -> Path:
    from wholebody.resources import bundled_file, tasks_dir

    found = bundled_file(name, path.parent) or bundled_file(name, tasks_dir())
    if found is not None:
        return found
    raise r.fail(
        "campaign.scenario",
        f"no scenario file {name!r} beside the campaign nor a "
        "bundled one (wholebody run --help lists them)",
    )


def _axes(r: TomlReader, raw: Any) -> Iterator[Axis]:
    if not isinstance(raw, list):
        raise r.fail("axes", "expected an array of tables ([[axes]])")
    seen: set[str] = set()
    for i, table in enumerate(raw):
        where = f"axes[{i}]"
        if not isinstance(table, dict):
            raise r.fail(where, "expected a table")
        r.only(table, where, ("key", "values", "uniform", "log_uniform", "choice"))
        key = r.string(table, "key", where)
        if key in seen:
            raise r.fail(f"{where}.key", f"{key!r} is varied by an earlier axis")
        seen.add(key)
        kinds = [k for k in ("values", "uniform", "log_uniform", "choice") if k in table]
        if len(kinds) != 1:
            raise r.fail(where, "expected exactly one of values, uniform, log_uniform, choice")
        yield _axis(r, where, key, kinds[0], table[kinds[0]])


def _axis(r: TomlReader, where: str, key: str, kind: str, raw: Any) -> Axis:
    at = f"{where}.{kind}"
    if not isinstance(raw, list) or not raw:
        raise r.fail(at, "expected a non-empty array")
    if kind in ("uniform", "log_uniform"):
        ok = (
            len(raw) == 2
            and all(isinstance(v, int | float) and not isinstance(v, bool) for v in raw)
            and raw[0] < raw[1]
        )
        if not ok or (kind == "log_uniform" and raw[0] <= 0):
            low = "0 < " if kind == "log_uniform" else ""
            raise r.fail(at, f"expected [low, high] with {low}low < high, got {raw!r}")
        return Axis(key, (), kind, (float(raw[0]), float(raw[1])))
    return Axis(key, tuple(raw)) if kind == "values" else Axis(key, (), "choice", tuple(raw))


def _check_values(r: TomlReader, campaign: Campaign) -> None:
    """Every axis value (a random axis: its bounds or choices) set alone on the base
    scenario, read by the scenario reader, and the run options checked; then, together, the
    cases of every grid point's first draw and every draw of the first grid point (a random
    integer key drawn as a real, an engine on a backend without one)."""
    if campaign.builtin is None:
        parse_scenario(campaign.scenario, campaign.scenario_path)
    for i, axis in enumerate(campaign.axes):
        for value in axis.values or axis.bounds:
            where = f"axes[{i}]"
            if axis.key == "backend" and value not in BACKENDS:
                raise r.fail(where, f"backend {value!r}: expected one of {', '.join(BACKENDS)}")
            if axis.key == "sim" and value not in SIMS:
                raise r.fail(where, f"sim {value!r}: expected one of {', '.join(SIMS)}")
            if axis.key == "engine":
                _check_engine(r, where, value)
                continue
            _try(r, campaign, Case(0, {axis.key: value}), where)
    cases = campaign.cases()
    robots: set[str] = set()
    for case in cases:
        if case.sample == 0 or case.index < campaign.samples:
            spec, options = _try(r, campaign, case, "axes")
            robots.add(spec.robot)
            _check_solver(r, campaign, case, spec.backend, options)
    if campaign.builtin is None:
        _check_robots(r, campaign, robots)


def _try(r: TomlReader, campaign: Campaign, case: Case, where: str):
    try:
        return campaign.case_spec(case)
    except ConfigError as exc:
        values = ", ".join(f"{k} = {v!r}" for k, v in case.values.items())
        raise r.fail(where, f"{values}: {exc}") from None


def _check_solver(
    r: TomlReader, campaign: Campaign, case: Case, backend: str, options: dict
) -> None:
    from wholebody.scenarios.runner import make_solver

    try:
        make_solver(options.get("backend") or backend, options.get("engine"))
    except ConfigError as exc:
        raise r.fail("axes", f"{case.name} ({case.values}): {exc}") from None


def _check_robots(r: TomlReader, campaign: Campaign, robots: set[str]) -> None:
    """Each robot the cases name loads (a robot directory beside the scenario, or bundled)."""
    from wholebody.scenarios.runner import scenario_robot

    for name in sorted(robots):
        data = copy.deepcopy(campaign.scenario)
        set_key(data, "scenario.robot", name)
        try:
            scenario_robot(parse_scenario(data, campaign.scenario_path))
        except Exception as exc:  # the robot's own error names what is wrong
            raise r.fail("axes", f"robot {name!r}: {exc}") from None


def _check_engine(r: TomlReader, where: str, value: Any) -> None:
    from wholebody.solvers.hqp import HierarchicalQPSolver

    try:
        HierarchicalQPSolver(value)
    except Exception as exc:  # the solver's own message names the engines
        raise r.fail(where, f"engine {value!r}: {exc}") from None


@functools.lru_cache(maxsize=4)
def _robot(name: str):
    """A robot loaded once per process (a campaign draws many targets on it)."""
    from wholebody.robot import load_robot

    return load_robot(name)


def random_target_scenario(campaign: Campaign, sample: int) -> dict[str, Any]:
    """The scenario of draw ``sample`` of the ``random_targets`` campaign (module docstring):
    the first arm's tool to the pose it has at a random configuration within the limits."""
    import pinocchio as pin

    name = campaign.builtin_options["robot"]
    local = campaign.path.parent / name
    robot_ref = str(local) if (local / "robot.toml").is_file() else name
    robot = _robot(robot_ref)
    if not robot.arms:
        raise ConfigError(
            f"{campaign.path}: robot {robot.name!r} has no [arms] in its "
            "robot.toml: random_targets moves the first arm's tool"
        )
    arm = next(iter(robot.arms.values()))
    rng = np.random.default_rng([campaign.seed, sample, 1])
    lo, hi = (np.clip(v, -np.pi, np.pi) for v in robot.position_limits)
    base = len(robot.base.actuators)
    joints = dict(zip(robot.actuated_joints[base:], rng.uniform(lo, hi)[base:], strict=True))
    start = robot.frame_pose(robot.home(), arm.tool)
    goal = robot.frame_pose(robot.configuration(joints), arm.tool)
    rotate = pin.log3(goal[:3, :3] @ start[:3, :3].T)
    return {
        FORMAT_KEY: SCENARIO.current,
        "scenario": {"name": f"random_target_{sample}", "robot": robot_ref, "start": "home"},
        "hands": {arm.name: {"frame": arm.tool.name}},
        "phases": [
            {
                "name": "reach",
                "duration": campaign.builtin_options["duration"],
                "hands": {
                    arm.name: {
                        "planner": "min_jerk",
                        "goal": goal[:3, 3].tolist(),
                        "rotate": rotate.tolist(),
                    }
                },
            }
        ],
    }
