"""The ``wholebody`` command line."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence
from pathlib import Path

from wholebody.errors import ConfigError, WholebodyError

__all__ = ["main"]


def _info(args: argparse.Namespace) -> int:
    from wholebody.robot import load_robot, robot_catalogue

    if args.list:
        for name, text, available in robot_catalogue():
            print(f"{name:<18} {text if available else 'unavailable: ' + text}")
        return 0
    print(load_robot(args.robot).summary())
    return 0


def _scenario_path(name: str) -> Path:
    """A scenario file path, or the name of a bundled one (``coordinated_carry``)."""
    from wholebody.resources import tasks_dir

    path = Path(name)
    if path.is_file():
        return path
    bundled = tasks_dir() / (name if name.endswith(".toml") else f"{name}.toml")
    if bundled.is_file():
        return bundled
    names = sorted(p.stem for p in tasks_dir().glob("*.toml"))
    raise ConfigError(f"no scenario {name!r}: expected a file or one of {', '.join(names)}")


def _display_available() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def _run_one(path: Path, backend: str | None, viz: bool, out: Path, hold: bool) -> int:
    from wholebody.scenarios import load_scenario, run_scenario
    from wholebody.scenarios.outputs import write_run

    spec = load_scenario(path)
    scene = live = None
    if viz:
        from wholebody.scenarios.runner import scenario_robot, start_configuration
        from wholebody.scenarios.visual import LiveView, draw_objects, show_run
        from wholebody.viz.scene import Scene

        scene = Scene(scenario_robot(spec))
        print(f"MeshCat (localhost only): {scene.url}")
        draw_objects(scene, spec)
        scene.show(start_configuration(spec, scene.robot))
        live = LiveView(scene, spec.dt)
    run = run_scenario(spec, backend=backend, progress=True, on_step=live)
    files = write_run(run, out)
    m = run.metrics
    print(
        f"{spec.name} [{run.backend}]: {len(run.log)} steps in {run.wall_time:.1f} s; "
        f"control step {m['step_time_us']['median']:.0f} us median "
        f"({m['frequency_hz']:.0f} Hz); limit violations {m['limit_violations']}, "
        f"solver failures {m['solver_failures']}"
    )
    for phase, entry in m["phases"].items():
        worst = max((v for hand in entry["mae_m"].values() for v in hand.values()), default=0.0)
        chain = entry.get("closed_chain_error_max_m")
        extra = f", closed chain <= {chain * 1e3:.3f} mm" if chain is not None else ""
        print(f"  {phase:16s} worst hand MAE {worst * 1e3:.3f} mm{extra}")
    for name, f in files.items():
        print(f"  {name:17s} {f}")
    if scene is not None:
        if hold:
            show_run(scene, run)
            print(f"replay: the run is loaded as an animation at {scene.url}")
            input("press Enter to close the viewer ")
        else:
            print("MeshCat viewer closed (stdin is not a terminal: nothing to wait on)")
        scene.close()
    return 0


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
    return _run_one(path, args.backend, args.viz, out, hold=args.viz and sys.stdin.isatty())


def _demo(args: argparse.Namespace) -> int:
    viz = args.viz or _display_available()
    if not viz:
        print("no display: running the demo headless (use --viz for the MeshCat viewer)")
    out = _output_dir(Path(args.out) if args.out else Path("runs") / "demo")
    return _run_one(
        _scenario_path("coordinated_carry"), None, viz, out, hold=viz and sys.stdin.isatty()
    )


def _compare(args: argparse.Namespace) -> int:
    from wholebody.scenarios import load_scenario, run_scenario
    from wholebody.scenarios.outputs import (
        comparison,
        comparison_markdown,
        write_comparison,
        write_run,
    )

    path = _scenario_path(args.scenario)
    spec = load_scenario(path)
    out = _output_dir(Path(args.out) if args.out else Path("runs") / f"{path.stem}_comparison")
    runs = []
    try:
        for backend in args.backends:  # each run's log and metrics kept as soon as it ends
            print(f"running {spec.name} with {backend} ...")
            run = run_scenario(spec, backend=backend, progress=True)
            write_run(run, out / backend, figures=False)
            runs.append(run)
    except KeyboardInterrupt:
        missing = args.backends[len(runs) :]
        if runs:
            write_comparison(runs, out)
        done = ", ".join(r.backend for r in runs) or "none"
        print(f"wholebody: interrupted: not run: {', '.join(missing)}; finished: {done} "
              f"(their logs, metrics and comparison are in {out})", file=sys.stderr)  # fmt: skip
        return 130
    files = write_comparison(runs, out)
    print(comparison_markdown(comparison(runs), spec.title or spec.name))
    for name, f in files.items():
        print(f"  {name:9s} {f}")
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


def build_parser() -> argparse.ArgumentParser:
    from wholebody.scenarios.spec import BACKENDS

    parser = argparse.ArgumentParser(
        prog="wholebody",
        description="Whole-body control of highly redundant mobile humanoids.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    info = sub.add_parser("info", help="describe a robot (bundled name, directory or robot.toml)")
    info.add_argument("robot", nargs="?", default="mobile_humanoid")
    info.add_argument("--list", action="store_true", help="list the bundled robots")
    info.set_defaults(func=_info)
    run = sub.add_parser("run", help="run a scenario file (or a bundled scenario's name)")
    run.add_argument("scenario")
    run.add_argument(
        "--backend",
        choices=BACKENDS,
        default=None,
        help="override the scenario's backend",
    )
    run.add_argument("--viz", action="store_true", help="live MeshCat view and replay")
    run.add_argument("--out", default=None, help="output directory (default runs/NAME)")
    run.set_defaults(func=_run)
    compare = sub.add_parser(
        "compare",
        help="the paper's Table 2 for a scenario: pseudo-inverse vs projection vs hierarchical QP",
    )
    compare.add_argument("scenario")
    compare.add_argument("--out", default=None, help="output directory")
    compare.add_argument(
        "--backends",
        nargs="+",
        default=["pinv", "projection", "hqp"],
        choices=BACKENDS,
    )
    compare.set_defaults(func=_compare)
    demo = sub.add_parser(
        "demo",
        help="the coordinated dual-arm carry: live in MeshCat with "
        "--viz or a display, headless otherwise",
    )
    demo.add_argument("--viz", action="store_true")
    demo.add_argument("--out", default=None, help="output directory (default runs/demo)")
    demo.set_defaults(func=_demo)
    warm = sub.add_parser("warmup", help="compile the kernels now (once per machine, cached)")
    warm.set_defaults(func=_warmup)
    from wholebody.humanlike.cli import add_stiffness_parser

    add_stiffness_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except WholebodyError as exc:
        print(f"wholebody: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        print(f"wholebody: {_interrupted(exc)}", file=sys.stderr)
        return 130


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
