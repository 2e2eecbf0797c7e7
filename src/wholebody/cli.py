"""The ``wholebody`` command line.

Building the parser imports nothing heavy (no Pinocchio, no kernels, no torch): ``--help``
and argument errors answer at once, and each command imports what it needs when it runs.
The ``stiffness`` subcommands' parser lives in :mod:`wholebody.humanlike.cli`, whose import
costs as much as a run's; it is built only when the command is ``stiffness`` (a placeholder
with the same one-line help stands in for it otherwise).
"""

from __future__ import annotations

import argparse
import signal
import sys
import textwrap
from collections.abc import Sequence
from pathlib import Path

from wholebody.errors import ConfigError, WholebodyError

__all__ = ["BACKENDS", "build_parser", "main"]

BACKENDS = ("projection", "pinv", "hqp", "dynamics")
"""The scenario backends (:data:`wholebody.scenarios.spec.BACKENDS`, repeated here so that
building the parser imports no solver; a test keeps the two equal)."""

STIFFNESS_HELP = "human-like stiffness: dataset, network training, report"
"""The ``stiffness`` command's one-line help (the same as :mod:`wholebody.humanlike.cli`'s;
a test keeps them equal)."""

FRAMES_SHOWN = 40
"""``info`` lists at most this many link frames unless ``--frames`` is given."""


def _frame_kinds(robot) -> dict[str, list[str]]:
    """The names :meth:`Robot.frame` accepts, by kind: ``links`` (URDF links), ``declared``
    (``[frames]`` of robot.toml) and ``joints`` (joints, fixed joints included), in the
    model's order."""
    import pinocchio as pin

    declared = set(robot.config.frames)
    kinds: dict[str, list[str]] = {"links": [], "declared": [], "joints": []}
    for f in robot.model.frames:
        if f.name == "universe":
            continue
        if f.name in declared:
            kinds["declared"].append(f.name)
        elif f.type == pin.FrameType.BODY:
            kinds["links"].append(f.name)
        elif f.type in (pin.FrameType.JOINT, pin.FrameType.FIXED_JOINT):
            kinds["joints"].append(f.name)
    return kinds


def _wrapped(label: str, names: list[str]) -> str:
    """``label`` then the comma-separated ``names``, wrapped at 100 columns."""
    return textwrap.fill(
        ", ".join(names),
        width=100,
        initial_indent=f"  {label}: ",
        subsequent_indent="    ",
        break_on_hyphens=False,
        break_long_words=False,
    )


def info_argument(robot) -> str:
    """What ``wholebody info`` takes to load ``robot`` again from any directory: a bundled
    robot's name, else the absolute path of its robot directory (quoted for a shell)."""
    import shlex

    from wholebody.resources import robots_dir

    path = Path(robot.config.path).resolve()
    if path == (robots_dir() / robot.name / "robot.toml").resolve():
        return robot.name
    return shlex.quote(str(path.parent if path.name == "robot.toml" else path))


def frames_text(robot, full: bool = False) -> str:
    """The frames a task can name: the arms' tool frames (the hand tasks' frames), then the
    link frames (at most :data:`FRAMES_SHOWN` unless ``full``) and the declared ones; with
    ``full``, also the joint frames."""
    kinds = _frame_kinds(robot)
    tools = [f"{arm.tool.name} (arm {name})" for name, arm in robot.arms.items()]
    lines = [_wrapped("tool frames (hand tasks)", tools or ["none: no [arms] in robot.toml"])]
    links = kinds["links"]
    shown = links if full or len(links) <= FRAMES_SHOWN else links[:FRAMES_SHOWN]
    more = len(links) - len(shown)
    tail = [f"... {more} more (wholebody info {info_argument(robot)} --frames)"] if more else []
    lines.append(_wrapped(f"link frames ({len(links)})", shown + tail))
    if kinds["declared"]:
        lines.append(_wrapped(f"declared frames ({len(kinds['declared'])})", kinds["declared"]))
    if full:
        lines.append(_wrapped(f"joint frames ({len(kinds['joints'])})", kinds["joints"]))
    else:
        lines.append("  (joint names are frames too; --frames lists every frame)")
    return "\n".join(lines)


def _info(args: argparse.Namespace) -> int:
    from wholebody.robot import load_robot, robot_catalogue

    if args.list:
        for name, text, available in robot_catalogue():
            print(f"{name:<18} {text if available else 'unavailable: ' + text}")
        return 0
    if args.suggest_frames:
        from wholebody.robot import read_robot_config, robot_toml
        from wholebody.robot.centres import centres_text

        print(centres_text(read_robot_config(robot_toml(args.robot))), end="")
        return 0
    robot = load_robot(args.robot)
    print(robot.summary())
    print(frames_text(robot, full=args.frames))
    return 0


def bundled_scenarios() -> list[str]:
    """The names of the scenario files that ship with the package (``tasks/*.toml``)."""
    from wholebody.resources import tasks_dir

    return sorted(p.stem for p in tasks_dir().glob("*.toml"))


def _scenario_path(name: str) -> Path:
    """A scenario file path, or the name of a bundled one (``coordinated_carry``)."""
    from wholebody.resources import tasks_dir

    return _file_or_bundled(name, tasks_dir(), "scenario")


def _file_or_bundled(name: str, folder: Path, what: str) -> Path:
    """``name`` as a file, else the bundled ``folder/name.toml``; else a
    :class:`ConfigError` listing the bundled ones."""
    from wholebody.resources import bundled_file

    path = Path(name)
    found = path if path.is_file() else bundled_file(name, folder)
    if found is None:
        names = ", ".join(sorted(p.stem for p in folder.glob("*.toml")))
        raise ConfigError(f"no {what} {name!r}: expected a file or one of {names}")
    return found


def _start_viewer(spec):
    """A MeshCat scene of the scenario at its start, framed on the start posture, the props
    and the phases' goals (the run's extent before it runs), and its live view."""
    import numpy as np

    from wholebody.scenarios.runner import scenario_robot, start_configuration
    from wholebody.scenarios.visual import LiveView, draw_objects
    from wholebody.viz.scene import Scene

    scene = Scene(scenario_robot(spec))
    draw_objects(scene, spec)
    q0 = start_configuration(spec, scene.robot)
    scene.show(q0)
    goals = [h.goal for p in spec.phases for h in p.hands.values() if h.goal is not None]
    scene.frame(np.array(goals, dtype=float).reshape(-1, 3), q=q0)
    print(f"MeshCat (localhost only): {scene.url} (the run is drawn live, at its real pace)")
    from wholebody.scenarios.runner import collision_model

    cs = spec.collision
    if cs is None:
        return scene, LiveView(scene, spec.dt)
    return scene, LiveView(
        scene,
        spec.dt,
        collision=collision_model(spec, scene.robot),
        influence=cs.influence,
        safety=cs.safety,
    )


def _replay(scene, run, out: Path, hold: bool) -> None:
    """Load the replay, save it as a standalone page and, on a terminal, keep the viewer
    open until Enter."""
    from wholebody.scenarios.visual import show_run

    show_run(scene, run)
    page = scene.save_html(out / "replay.html")
    print(f"  replay            {page} (a standalone page: open it in a browser, no server)")
    if hold:
        print(
            f"MeshCat at {scene.url} replays the run (the page's Animations controls replay "
            "it); press Enter here to close the viewer and exit"
        )
        try:
            input()
        except (EOFError, KeyboardInterrupt):  # Ctrl-C or Ctrl-D leave the viewer too
            print()
    else:
        print("no terminal to wait on: the MeshCat server is closed; open the replay page")


def _run_one(
    path: Path,
    backend: str | None,
    viz: bool,
    out: Path,
    hold: bool,
    sim: str = "kinematic",
    sensor=None,
) -> int:
    """Run a scenario, write its outputs, report it; 1 if a physics run was stopped."""
    from wholebody.scenarios import load_scenario, run_scenario
    from wholebody.scenarios.outputs import write_run

    spec = load_scenario(path)
    scene, live = _start_viewer(spec) if viz else (None, None)
    try:
        run = run_scenario(
            spec,
            backend=backend,
            progress=True,
            on_step=live,
            sim=sim,
            on_objects=live.update_objects if live else None,
            sensor=sensor,
        )
        files = write_run(run, out)
        _report_run(run, files)
        if scene is not None:
            _replay(scene, run, out, hold)
    finally:
        if scene is not None:
            scene.close()
    if run.metrics.get("stopped"):
        print(f"wholebody: the run stopped early: {run.metrics['stopped']}", file=sys.stderr)
        return 1
    return 0


def _overshoot(m: dict) -> str:
    """How far past a limit the joints went, when they did."""
    if not m["limit_violations"]:
        return ""
    return f" (at most {1e3 * m['limit_violation_max']:.2f} mrad or mm past a limit)"


def _report_physics(m: dict) -> None:
    """A physics run's summary lines: torque peaks, saturation, grasps, contacts, speed."""
    peaks = ", ".join(
        f"{g} {v:.0f} N m ({100 * m['torque_peak_fraction'][g]:.0f} %)"
        for g, v in m["torque_peak_nm"].items()
    )
    print(f"  physics (MuJoCo)  {m['real_time_factor']:.1f}x real time; peak torque {peaks}")
    if "sensor" in m:
        s = m["sensor"]
        hands = ", ".join(
            f"{h} {1e3 * m['true_mean_tracking_error_m'][h]:.3f} / {1e3 * v:.3f}"
            for h, v in m["true_max_tracking_error_m"].items()
        )
        print(
            f"  sensor: noise {s['noise_rad_or_m']:g} rad or m, delay {s['delay_periods']} "
            f"periods ({s['latency_compensated_periods']} compensated); true hand error "
            f"mean / max (mm) {hands}; true closed chain <= "
            f"{1e3 * m['true_closed_chain_error_max_m']:.3f} mm"
        )
    if m["torque_saturated"]:
        worst = sorted(m["torque_saturated"].items(), key=lambda x: -x[1])[:3]
        print(
            "  at the torque limit: " + ", ".join(f"{j} {100 * f:.1f} % of steps" for j, f in worst)
        )
    for obj, hands in m["grasp_force_peak_n"].items():
        squeeze = m["squeeze_force_n"].get(obj)
        extra = (
            f"; squeeze peak {squeeze['peak']:.1f} N, mean {squeeze['mean']:.1f} N"
            if squeeze
            else ""
        )
        grips = ", ".join(f"{h} {f:.1f} N" for h, f in hands.items())
        print(f"  grasp of {obj}: peak force {grips}{extra}")
    for c in m["contacts"][:5]:
        print(f"  contact {c['pair']} from {c['first_s']:.2f} s, up to {c['peak_force_n']:.1f} N")


def _unmet_words(m: dict) -> str:
    """The steps with a task unmet in words, by cause, most severe first, with the tasks
    concerned (``m``: a run's metrics, :func:`wholebody.control.metrics.summary`); "" when
    every task was met (or the log did not record why)."""
    from wholebody.solvers.unmet import CAUSE_WORDS, UnmetCause

    steps, tasks = m.get("unmet_steps") or {}, m.get("unmet_tasks") or {}
    if not steps:
        return ""
    parts = []
    for cause in sorted(CAUSE_WORDS, reverse=True):
        key = cause.name.lower()
        if steps.get(key):
            names = ", ".join(t for t, c in tasks.items() if c.get(key))
            parts.append(f"{steps[key]} {CAUSE_WORDS[cause]}: {names}")
    total = sum(steps.values())
    failed = steps.get(UnmetCause.FAILED.name.lower(), 0)
    verdict = f"{failed} of them failures" if failed else "none a failure"
    return f"{total} steps with a task unmet, {verdict}: " + "; ".join(parts)


def _goal_words(m: dict) -> str:
    """Where each tracked hand ended against its goal, in words: "reached", or "ends 11.5 mm
    / 0.020 rad from its goal" beyond the tolerance (stated); "" without tracked hands."""
    from wholebody.control.metrics import GOAL_TOLERANCE_M, GOAL_TOLERANCE_RAD

    ends = m.get("final_error") or {}
    if not ends:
        return ""
    words = []
    for task, e in ends.items():
        if e["reached"]:
            words.append(f"{task} reached")
            continue
        rot = "" if e["rotation_rad"] is None else f" / {e['rotation_rad']:.3f} rad"
        words.append(f"{task} ends {e['position_m'] * 1e3:.1f} mm{rot} from its goal")
    return (
        ", ".join(words) + f" (tolerance {GOAL_TOLERANCE_M * 1e3:g} mm / "
        f"{GOAL_TOLERANCE_RAD:g} rad)"
    )


def _report_run(run, files: dict[str, Path]) -> None:
    """The run's summary lines: steps, control step timing, safety counts, the unmet tasks by
    cause, where the hands ended, worst hand error per phase, the files written."""
    m = run.metrics
    print(
        f"{run.spec.name} [{run.backend}{', MuJoCo' if m.get('sim') == 'mujoco' else ''}]: "
        f"{len(run.log)} steps in {run.wall_time:.1f} s; "
        f"control step median {m['step_time_us']['median']:.0f} us "
        f"(1/median = {m['median_step_rate_hz']:.0f} Hz); limit violations "
        f"{m['limit_violations']}{_overshoot(m)}, solver failures {m['solver_failures']}"
    )
    for label, text in (("unmet", _unmet_words(m)), ("goals", _goal_words(m))):
        if text:
            print(f"  {label:16s} {text}")
    for phase, entry in m["phases"].items():
        worst = max((v for hand in entry["mae_m"].values() for v in hand.values()), default=0.0)
        chain = entry.get("closed_chain_error_max_m")
        extra = f", closed chain <= {chain * 1e3:.3f} mm" if chain is not None else ""
        print(f"  {phase:16s} worst hand MAE {worst * 1e3:.3f} mm{extra}")
    if m.get("collision_pairs"):
        print(f"  collision: {m['collision_pairs']}")
    if m.get("min_collision_distance_m") is not None:
        print(
            f"  closest pair {m['min_collision_pair']}: {m['min_collision_distance_m'] * 1e3:.2f}"
            f" mm at {m['min_collision_time_s']:.2f} s"
        )
        for entry in m["collision_limited"]:
            print(f"  {entry['pair']} held {entry['task']} back for {entry['steps']} steps")
    if m.get("sim") == "mujoco":
        _report_physics(m)
    if "violation_max" in m:
        _report_torque(m)
    for name, f in files.items():
        print(f"  {name:17s} {f}")


def _report_torque(m: dict) -> None:
    """A torque-level run's line: the bounds, and whether the robot stood."""
    cop = m.get("cop_margin_min_m")
    parts = [f"bounds exceeded by at most {m['violation_max']:.2g} N m or N"]
    if cop is not None:
        parts.append(f"CoP at least {cop * 1e3:.1f} mm inside the soles")
    for obj, err in m.get("squeeze_error_max_n", {}).items():
        parts.append(f"{obj}'s squeeze within {err:.2f} N of its setpoint")
    if "fell" in m:
        parts += [
            f"contacts slid {m['foot_slip_max_m_all'] * 1e3:.2f} mm",
            f"CoM moved {m['com_excursion_max_m'] * 1e3:.1f} mm",
            "FELL" if m["fell"] else "stood",
        ]
    print("  torque level     " + "; ".join(parts))


def _output_dir(out: Path) -> Path:
    """``out``, made (with its parents) before a run so that a bad path does not cost the
    run."""
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {out}: exists and is not a directory")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"--out {out}: cannot make the directory: {exc.strerror}") from None
    return out


def _run(args: argparse.Namespace) -> int:
    path = _scenario_path(args.scenario)
    out = _output_dir(Path(args.out) if args.out else Path("runs") / path.stem)
    return _run_one(
        path,
        args.backend,
        args.viz,
        out,
        hold=args.viz and sys.stdin.isatty(),
        sim=args.sim,
        sensor=_sensor(args),
    )


def _demo(args: argparse.Namespace) -> int:
    if not args.viz:
        print(
            "running the demo headless: figures and logs only (add --viz for the live "
            "MeshCat viewer and a replay page)"
        )
    out = _output_dir(Path(args.out) if args.out else Path("runs") / "demo")
    return _run_one(
        _scenario_path("coordinated_carry"),
        None,
        args.viz,
        out,
        hold=args.viz and sys.stdin.isatty(),
    )


def _compare(args: argparse.Namespace) -> int:
    from wholebody.scenarios import load_scenario, run_scenario
    from wholebody.scenarios.outputs import (
        comparison,
        comparison_markdown,
        write_comparison,
        write_figures,
        write_run,
    )

    path = _scenario_path(args.scenario)
    spec = load_scenario(path)
    out = _output_dir(Path(args.out) if args.out else Path("runs") / f"{path.stem}_comparison")
    runs = []
    try:
        for backend in args.backends:  # each run's log, metrics, figures kept as it ends
            print(f"running {spec.name} with {backend} ...")
            run = run_scenario(
                spec, backend=backend, progress=True, sim=args.sim, sensor=_sensor(args)
            )
            write_run(run, out / backend, figures=False)
            runs.append(run)
            write_figures(run, out / backend)
    except KeyboardInterrupt:
        missing = [b for b in args.backends if b not in {r.backend for r in runs}]
        if runs:
            write_comparison(runs, out)
        done = ", ".join(r.backend for r in runs) or "none"
        print(
            f"wholebody: interrupted: not run: {', '.join(missing)}; finished: {done} "
            f"(their logs, metrics and comparison are in {out})",
            file=sys.stderr,
        )
        return 130
    files = write_comparison(runs, out)
    print(comparison_markdown(comparison(runs), spec.title or spec.name))
    for backend in args.backends:
        print(f"  {backend:10s} {out / backend}/ (run.npz, metrics.json, figures)")
    for name, f in files.items():
        print(f"  {name:10s} {f}")
    return 0


def _warmup(args: argparse.Namespace) -> int:
    from wholebody.warmup import warmup

    done = warmup()
    if not done.compiled:
        print("NUMBA_DISABLE_JIT=1: the kernels run as plain Python, nothing to compile")
        return 0
    where = done.cache or "nowhere (no writable cache directory: every process compiles)"
    print(f"kernels ready in {done.seconds:.1f} s, cached in {where}")
    return 0


def _scenario_help(what: str) -> str:
    """Help for a scenario argument, naming the bundled scenarios."""
    return f"{what}: a scenario file or a bundled name: {', '.join(bundled_scenarios())}"


def _add_sim_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--sim",
        choices=("kinematic", "mujoco"),
        default="kinematic",
        help="kinematic: the commands integrated exactly (default); mujoco: "
        "physics in the loop (the sim extra): joint servos with torque "
        "limits, objects with mass, grasps as welds",
    )
    parser.add_argument(
        "--sensor-noise",
        type=float,
        default=0.0,
        metavar="A",
        help="with --sim mujoco: uniform noise of half-width A on every "
        "encoder the controller reads (rad, m for a prismatic joint; "
        "default 0)",
    )
    parser.add_argument(
        "--sensor-delay",
        type=int,
        default=0,
        metavar="N",
        help="with --sim mujoco: the controller sees the state measured N "
        "control periods ago (default 0)",
    )
    parser.add_argument(
        "--sensor-seed",
        type=int,
        default=0,
        metavar="S",
        help="seed of the sensor noise (default 0)",
    )


def _sensor(args: argparse.Namespace):
    """The ``--sensor-*`` options as a :class:`~wholebody.control.JointSensor` (None when
    exact); a :class:`ConfigError` for a bad value or without ``--sim mujoco``."""
    from wholebody.control import JointSensor

    sensor = JointSensor(args.sensor_noise, args.sensor_delay, args.sensor_seed)
    if sensor.exact:
        return None
    if args.sim != "mujoco":
        raise ConfigError(
            "--sensor-noise and --sensor-delay model what a physics run's "
            "controller reads: add --sim mujoco"
        )
    return sensor


def _add_scenario_commands(sub: argparse._SubParsersAction) -> None:
    """``run``, ``compare`` and ``demo``."""
    run = sub.add_parser("run", help="run a scenario file (or a bundled scenario's name)")
    run.add_argument("scenario", metavar="SCENARIO", help=_scenario_help("what to run"))
    run.add_argument(
        "--backend", choices=BACKENDS, default=None, help="override the scenario's backend"
    )
    run.add_argument(
        "--viz",
        action="store_true",
        help="draw the run live in MeshCat (localhost), then write replay.html "
        "(a standalone replay) and, on a terminal, keep the viewer open until "
        "Enter",
    )
    run.add_argument("--out", default=None, help="output directory (default runs/NAME)")
    _add_sim_option(run)
    run.set_defaults(func=_run)
    compare = sub.add_parser(
        "compare",
        help="the paper's Table 2 for a scenario: pseudo-inverse vs projection vs hierarchical QP",
    )
    compare.add_argument("scenario", metavar="SCENARIO", help=_scenario_help("what to run"))
    compare.add_argument(
        "--out",
        default=None,
        help="output directory (default "
        "runs/NAME_comparison; each backend's run, metrics and figures in "
        "its BACKEND/ subdirectory)",
    )
    compare.add_argument(
        "--backends", nargs="+", default=["pinv", "projection", "hqp"], choices=BACKENDS
    )
    _add_sim_option(compare)
    compare.set_defaults(func=_compare)
    demo = sub.add_parser(
        "demo",
        help="the coordinated dual-arm carry: headless (figures and logs), live in MeshCat "
        "with --viz",
    )
    demo.add_argument(
        "--viz",
        action="store_true",
        help="draw it live in MeshCat and write replay.html; on a terminal the "
        "viewer stays open until Enter",
    )
    demo.add_argument("--out", default=None, help="output directory (default runs/demo)")
    demo.set_defaults(func=_demo)


def _add_sweep_command(sub: argparse._SubParsersAction) -> None:
    """``sweep``: a campaign's cases on local processes or Ray."""
    sweep = sub.add_parser(
        "sweep",
        help="run a campaign (a scenario with keys varied) on "
        "every core, or on a Ray cluster with --ray",
    )
    sweep.add_argument(
        "campaign",
        metavar="CAMPAIGN",
        help="a campaign file (TOML) or a bundled one's name: carry_weights, panda_targets",
    )
    sweep.add_argument(
        "--out",
        required=True,
        help="directory of the results: one file per "
        "case, results.csv, best.md, plots; a sweep started again on it runs "
        "only the missing cases",
    )
    sweep.add_argument(
        "--workers", type=int, default=None, help="local processes (default: every core)"
    )
    sweep.add_argument(
        "--ray",
        nargs="?",
        const="",
        default=None,
        metavar="ADDRESS",
        help="run the cases as Ray tasks: on the cluster at ADDRESS "
        "(HOST:PORT), or without it on a local Ray instance",
    )
    sweep.add_argument(
        "--ray-public",
        action="store_true",
        help="let the local Ray instance listen on the network, as Ray "
        "chooses (by default it is kept on 127.0.0.1, or refused): anyone "
        "who reaches this host can then submit work to it",
    )
    sweep.add_argument(
        "--timeout",
        type=float,
        default=None,
        metavar="S",
        help="stop a case after S seconds of wall time and record it as "
        "'timeout' (default: no limit)",
    )
    sweep.add_argument(
        "--retry-failed", action="store_true", help="run the cases that failed before again"
    )
    sweep.set_defaults(func=_sweep)


ROS_BACKENDS = ("projection", "hqp")


def _rate(text: str) -> float:
    """A ``--rate`` in Hz: a finite number > 0."""
    try:
        rate = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a rate in Hz, got {text!r}") from None
    if not 0 < rate < float("inf"):
        raise argparse.ArgumentTypeError(f"the rate must be > 0 Hz, got {text}")
    return rate


def _add_ros_commands(sub: argparse._SubParsersAction) -> None:
    """``ros`` (the controller as a ROS 2 node) and ``ros-sim`` (a simulated robot)."""
    ros = sub.add_parser(
        "ros",
        help="run the controller as a ROS 2 node (the ros extra): "
        "joint states and targets in, velocity commands out",
    )
    ros.add_argument("robot", metavar="ROBOT", help="bundled name, directory or robot.toml")
    ros.add_argument(
        "--task",
        action="extend",
        nargs="+",
        default=None,
        metavar="FRAME",
        help="the frames to control (default: the arms' tool "
        "frames); its target topic is /wholebody/FRAME/target",
    )
    ros.add_argument(
        "--stack",
        default=None,
        metavar="FILE",
        help="run a scenario file's [stack] and hands instead of the default "
        "stack (frame tasks, a posture, the limits)",
    )
    ros.add_argument("--backend", choices=ROS_BACKENDS, default="projection")
    ros.add_argument(
        "--rate", type=_rate, default=100.0, metavar="HZ", help="control rate (default 100 Hz)"
    )
    ros.set_defaults(func=_ros)
    sim = sub.add_parser(
        "ros-sim",
        help="a simulated robot on ROS 2 (the ros extra): "
        "publishes /joint_states (and /odom), integrates the "
        "commands",
    )
    sim.add_argument("robot", metavar="ROBOT", help="bundled name, directory or robot.toml")
    sim.add_argument(
        "--sim",
        choices=("kinematic", "mujoco"),
        default="kinematic",
        help="kinematic: the commands integrated exactly (default); mujoco: "
        "physics with joint servos (the sim extra)",
    )
    sim.add_argument(
        "--rate", type=_rate, default=100.0, metavar="HZ", help="state rate (default 100 Hz)"
    )
    sim.set_defaults(func=_ros_sim)


def _ros_ready() -> None:
    """ROS discovery on this host unless set otherwise, and rclpy importable (else a
    ConfigError saying what to install)."""
    from wholebody.ros.environment import require_rclpy, ros_environment

    ros_environment()
    require_rclpy()


def _ros(args: argparse.Namespace) -> int:
    if args.stack is not None and args.task:
        raise ConfigError("--task and --stack: a scenario's stack names its own frames")
    _ros_ready()
    from wholebody.ros.node import start

    return start(args.robot, args.task, args.stack, args.backend, args.rate, args.ros_args)


def _ros_sim(args: argparse.Namespace) -> int:
    _ros_ready()
    from wholebody.ros.sim_node import start

    return start(args.robot, args.sim, args.rate, args.ros_args)


def _terminated(signum: int, frame: object) -> None:
    raise KeyboardInterrupt


def _campaign_path(name: str) -> Path:
    """A campaign file, or the name of a bundled one (``tasks/campaigns``)."""
    from wholebody.resources import tasks_dir

    return _file_or_bundled(name, tasks_dir() / "campaigns", "campaign")


def _sweep(args: argparse.Namespace) -> int:
    from wholebody.sweep import load_campaign, run_sweep

    if args.workers is not None and args.workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {args.workers}")
    if args.ray_public and args.ray != "":
        raise ConfigError("--ray-public is for a local Ray instance: --ray without an address")
    campaign = load_campaign(_campaign_path(args.campaign))
    out = _output_dir(Path(args.out))
    signal.signal(signal.SIGTERM, _terminated)  # a scheduler's stop: as a Ctrl-C
    try:
        result = run_sweep(
            campaign,
            out,
            workers=args.workers,
            ray=args.ray is not None,
            address=args.ray or None,
            retry_failed=args.retry_failed,
            ray_public=args.ray_public,
            timeout=args.timeout,
        )
    except KeyboardInterrupt:
        done = len(list((out / "cases").glob("case_*.json")))
        print(
            f"wholebody: interrupted: {done} finished cases are in {out / 'cases'} (and "
            f"results.csv); the same command runs the others",
            file=sys.stderr,
        )
        return 130
    print(
        f"{campaign.name}: {result.cases} cases, {result.found} found finished in {out}, "
        f"{result.ran} run now in {result.wall_time:.1f} s; {result.failed} failed"
    )
    print((out / "best.md").read_text())
    for name, path in result.files.items():
        print(f"  {name:8s} {path}")
    return 1 if result.rows and result.failed == len(result.rows) else 0


def _add_humanlike_command(sub: argparse._SubParsersAction) -> None:
    """``humanlike evaluate``: the motion test on people."""
    hl = sub.add_parser(
        "humanlike",
        help="the motion test on people: the robot's arm angle against recorded persons'",
    )
    hsub = hl.add_subparsers(dest="humanlike_command", required=True, metavar="COMMAND")
    ev = hsub.add_parser(
        "evaluate",
        help="drive the robot's wrist along recorded wrist paths "
        "with each controller; compare arm angles frame by frame",
    )
    ev.add_argument(
        "--recordings",
        default=None,
        help="a directory of recordings (CSV or NPZ, the shipped format); default "
        "the bundled real ones",
    )
    ev.add_argument("--out", required=True, help="output directory (humanlike.json, .png)")
    ev.add_argument(
        "--participants", default=None, help="comma-separated participants to keep (default: all)"
    )
    ev.add_argument("--robot", default="mobile_humanoid")
    ev.add_argument("--every", type=int, default=1, help="every N-th trial (default all)")
    ev.add_argument(
        "--held-out",
        action="store_true",
        help="pull each participant's trials towards an arm-angle network trained "
        "without them (one per participant, on every recording of --recordings; "
        "needs the learn extra), not the shipped one",
    )
    ev.set_defaults(func=_humanlike_evaluate)


def _humanlike_evaluate(args: argparse.Namespace) -> int:
    from wholebody.humanlike.recordings import load_recordings
    from wholebody.robot import load_robot
    from wholebody.scenarios.human_motion import (
        CONTROLLERS,
        evaluate,
        held_out_arm_angle_models,
        write_report,
    )

    if args.every < 1:
        raise ConfigError(f"--every must be >= 1, got {args.every}")
    every = load_recordings(args.recordings)
    recs = every
    if args.participants:
        keep = {p.strip() for p in args.participants.split(",") if p.strip()}
        recs = [r for r in every if r.participant in keep]
        missing = keep - {r.participant for r in recs}
        if missing:
            raise ConfigError(f"--participants: no recordings of {', '.join(sorted(missing))}")
    recs = recs[:: args.every]
    models = None
    if args.held_out:  # trained on every recording but the participant's own
        models = held_out_arm_angle_models(every, only=sorted({r.participant for r in recs}))
    else:
        print(
            "arm-angle model: the shipped one, trained on the bundled participants "
            "(in-sample for them; --held-out for a test on people it never saw)"
        )
    robot = load_robot(args.robot)
    scores = evaluate(robot, recs, CONTROLLERS, arm_angle_model=models)
    meta = {
        "robot": robot.name,
        "trials": [r.name for r in recs],
        "participants": sorted({r.participant for r in recs}),
        "arm_angle_model": "held out (one per participant)" if args.held_out else "shipped",
    }
    written = write_report(scores, Path(args.out), meta)
    print(f"{len(recs)} trials of {len(meta['participants'])} participants on {robot.name}")
    people = meta["participants"]
    print(
        f"  {'arm angle rms (deg)':<19}{'all':>6}{'95 % (people)':>15}"
        + "".join(f"{p:>8}" for p in people)
    )
    for name, sc in scores.items():
        by, (lo, hi) = sc.alpha_rms_deg_by_participant, sc.alpha_rms_deg_interval
        print(
            f"  {name:<19}{sc.alpha_rms_deg:6.1f}{f'[{lo:.1f}, {hi:.1f}]':>15}"
            + "".join(f"{by[p]:8.1f}" for p in people)
        )
    print(
        f"  {'waist travel (rad)':<19}{'/ trial':>6}{'95 % (people)':>15}"
        + "".join(f"{p:>8}" for p in people)
        + f"{'total':>9}"
    )
    for name, sc in scores.items():
        lo, hi = sc.waist_travel_rad_per_trial_interval
        print(
            f"  {name:<19}{sc.waist_travel_rad_per_trial:6.2f}{f'[{lo:.2f}, {hi:.2f}]':>15}"
            + "".join(f"{sc.participants[p].waist_travel_rad_per_trial:8.2f}" for p in people)
            + f"{sc.waist_travel_rad:9.1f}"
        )
    for name, sc in scores.items():
        print(
            f"  {name:<19}wrist error median {sc.wrist_error_median_mm:.2f} mm, "
            f"max {sc.wrist_error_mm:.1f} mm"
        )
    for what, path in written.items():
        print(f"  {what:<5} {path}")
    return 0


def build_parser(stiffness: bool = True) -> argparse.ArgumentParser:
    """The command line's parser. ``stiffness``: the ``stiffness`` subcommands' real parser
    (it imports the stiffness pipeline); else a placeholder with the same help line."""
    parser = argparse.ArgumentParser(
        prog="wholebody",
        description="Whole-body control of highly redundant mobile humanoids.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    info = sub.add_parser(
        "info",
        help="describe a robot (bundled name, directory or "
        "robot.toml): groups, arms, tool frames and frames",
    )
    info.add_argument("robot", nargs="?", default="mobile_humanoid")
    info.add_argument("--list", action="store_true", help="list the bundled robots")
    info.add_argument(
        "--frames", action="store_true", help="list every frame a task can name (and joints)"
    )
    info.add_argument(
        "--suggest-frames",
        action="store_true",
        help="for arms whose shoulder, elbow or wrist frames are not joint "
        "centres: [frames] entries placing them there, to paste into "
        "robot.toml",
    )
    info.set_defaults(func=_info)
    _add_scenario_commands(sub)
    _add_sweep_command(sub)
    warm = sub.add_parser("warmup", help="compile the kernels now (once per machine, cached)")
    warm.set_defaults(func=_warmup)
    _add_humanlike_command(sub)
    _add_ros_commands(sub)
    if stiffness:
        from wholebody.humanlike.cli import add_stiffness_parser

        add_stiffness_parser(sub)
    else:
        sub.add_parser("stiffness", help=STIFFNESS_HELP, add_help=False)
    return parser


def _split_ros_args(argv: list[str]) -> tuple[list[str], list[str]]:
    """``argv`` before ``--ros-args``, and ``--ros-args`` with what follows (ROS's own
    arguments: remappings, parameters, log levels), which go to rclpy as they are."""
    if "--ros-args" not in argv:
        return argv, []
    i = argv.index("--ros-args")
    return argv[:i], argv[i:]


def _command(argv: Sequence[str]) -> str | None:
    """The subcommand's name in ``argv`` (its first word not starting with ``-``)."""
    return next((a for a in argv if not a.startswith("-")), None)


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser(stiffness=_command(argv) == "stiffness")
    argv, ros_args = _split_ros_args(argv)
    args = parser.parse_args(argv)
    args.ros_args = ros_args
    if ros_args and args.command not in ("ros", "ros-sim"):
        parser.error("--ros-args is for the ros and ros-sim commands")
    try:
        return int(args.func(args) or 0)
    except BrokenPipeError:  # the reader left (``wholebody info | head -1``)
        return _reader_gone()
    except WholebodyError as exc:
        print(f"wholebody: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        print(f"wholebody: {_interrupted(exc)}", file=sys.stderr)
        return 130


def _reader_gone() -> int:
    """Standard output's reader has closed the pipe: what is left to print goes nowhere
    (stdout is pointed at the null device, so the interpreter's last flush does not fail
    again), and the exit status is a program's stopped by SIGPIPE, 128 + 13."""
    import contextlib
    import os

    # without a file descriptor (a test's capture) there is no flush to fail
    with contextlib.suppress(OSError, ValueError, AttributeError):
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return 141


def _interrupted(exc: KeyboardInterrupt) -> str:
    """What a Ctrl-C left: the files written (each complete) and those not written."""
    written: dict[str, Path] = getattr(exc, "written", {})
    missing: list[str] = getattr(exc, "missing", [])
    if not missing:
        return "interrupted before any output was written (existing files are unchanged)"
    done = ", ".join(str(p) for p in written.values()) or "none"
    return f"interrupted: written, complete: {done}; not written: {', '.join(missing)}"


if __name__ == "__main__":
    raise SystemExit(main())
