#!/usr/bin/env python3
"""TSID 1.10 on the TALOS standing problem, run in its own virtual environment (issue 35).

TSID's wheels need cmeel-boost 1.90 and the pin release they were built against, not the dev
venv's, so TSID lives in ``benchmarks/.venvs/tsid`` (made by
``bash benchmarks/peers/tsid/setup.sh``) and runs as a subprocess:
``benchmarks/peers/tsid/talos_stand.py`` reads a JSON problem on stdin and prints a JSON
result (its docstring states the problem, the formulation and what is measured).

As a module (other benchmark scripts in this directory: ``from tsid_peer import ...``):

* :func:`default_problem` -- the problem with every field, the script's defaults with
  ``robots/talos_full/robot.toml``'s locked joints and home posture;
* :func:`run_tsid` -- one run of the script on a problem, its result as a dict.

As a script: ``python benchmarks/tsid_peer.py`` runs the default problem ``--repeat`` times
(the solvers interleaved within each repeat) and prints a table, with the medians over the
repeats.
"""

from __future__ import annotations

import argparse
import ast
import json
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import numpy as np

BENCHMARKS = Path(__file__).resolve().parent
VENV_PYTHON = BENCHMARKS / ".venvs" / "tsid" / "bin" / "python"
SCRIPT = BENCHMARKS / "peers" / "tsid" / "talos_stand.py"
SETUP_COMMAND = "bash benchmarks/peers/tsid/setup.sh"
SOLVERS = ("eiquadprog-fast", "eiquadprog")  # what TSID 1.10's Python bindings offer
# TSID's import registers a boost converter twice and says so on stderr: not a problem.
QUIET = "ignore:to-Python converter:RuntimeWarning"


class TsidPeerError(RuntimeError):
    """TSID's run could not be made: its venv is missing, or the script failed."""


def script_defaults() -> dict[str, Any]:
    """``DEFAULTS`` of ``talos_stand.py``, read from its source (a literal dict): the script
    imports tsid, which the dev venv does not have, so it is not imported."""
    tree = ast.parse(SCRIPT.read_text(), str(SCRIPT))
    for node in tree.body:
        if isinstance(node, ast.AnnAssign | ast.Assign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            if any(isinstance(t, ast.Name) and t.id == "DEFAULTS" for t in targets):
                assert node.value is not None
                return ast.literal_eval(node.value)
    raise TsidPeerError(f"no DEFAULTS dict in {SCRIPT}")


def default_problem(**changes: Any) -> dict[str, Any]:
    """The TALOS standing problem with every field: the script's defaults (sole 0.2 x 0.13 m,
    mu 0.3, 5..1500 N, CoM sine 5 cm at 0.5 Hz along y, 2000 steps of 1 ms, ...), the locked
    joints (``[locked]``, fnmatch patterns allowed) and the posture (``[home]``, the other
    joints at 0) of ``robots/talos_full/robot.toml``; then ``changes`` (unknown keys are an
    error)."""
    from wholebody.resources import robots_dir
    from wholebody.tomlreader import tomllib  # the standard library's, or tomli before 3.11

    problem = script_defaults()
    unknown = sorted(set(changes) - set(problem))
    if unknown:
        raise ValueError(f"unknown problem keys {unknown}; known: {sorted(problem)}")
    config = tomllib.loads((robots_dir() / "talos_full" / "robot.toml").read_text())
    problem["locked"] = dict(config.get("locked", {}))
    problem["q0"] = dict(config["home"])
    problem.update(changes)
    return problem


def run_tsid(problem: dict[str, Any], timeout: float = 600) -> dict[str, Any]:
    """Run ``talos_stand.py`` in TSID's venv on ``problem`` (a JSON-serialisable dict, keys
    as in the script's ``DEFAULTS``; missing keys take their defaults) and return its JSON
    result. :class:`TsidPeerError` when the venv is missing (with the command that makes it),
    on a timeout (``timeout`` s) or when the script fails (with its stderr)."""
    if not VENV_PYTHON.exists():
        raise TsidPeerError(
            f"TSID's virtual environment is missing ({VENV_PYTHON} not found): "
            f"run `{SETUP_COMMAND}` from the checkout first"
        )
    command = [str(VENV_PYTHON), "-W", QUIET, str(SCRIPT)]
    try:
        done = subprocess.run(
            command,
            input=json.dumps(problem),
            capture_output=True,
            text=True,
            timeout=timeout,
            check=False,
        )
    except subprocess.TimeoutExpired as exc:
        raise TsidPeerError(f"TSID's run took more than {timeout:g} s: {command}") from exc
    if done.returncode != 0:
        tail = "\n".join(done.stderr.strip().splitlines()[-15:])
        raise TsidPeerError(f"TSID's run failed (exit status {done.returncode}):\n{tail}")
    return json.loads(done.stdout)


COLUMNS = (  # header, unit, value of a result
    ("solve", "us", lambda r: r["solve_us"]["median"]),
    ("p10", "us", lambda r: r["solve_us"]["p10"]),
    ("p90", "us", lambda r: r["solve_us"]["p90"]),
    ("compute", "us", lambda r: r["compute_us"]["median"]),
    ("qp", "us", lambda r: r["qp_us"]["median"]),
    ("step", "us", lambda r: r["step_us"]["median"]),
    ("CoM rms", "mm", lambda r: 1e3 * r["com_error_m"]["rms"]),
    ("CoM max", "mm", lambda r: 1e3 * r["com_error_m"]["max"]),
    ("rms 2/2", "mm", lambda r: 1e3 * r["com_error_second_half_m"]["rms"]),
    ("drift", "um", lambda r: 1e6 * max(f["translation_m"] for f in r["feet_drift"].values())),
    ("CoP mrg", "mm", lambda r: 1e3 * r["cop_margin_min_m"]),
    ("mrg 2/2", "mm", lambda r: 1e3 * r["cop_margin_second_half_min_m"]),
    ("tau/max", "", lambda r: r["torque_ratio_max"]),
    ("fails", "", lambda r: r["solver_failures"]),
)
"""The table's columns: times are medians over the steps of one run."""


def value(get: Any, r: dict[str, Any]) -> float:
    """A column's value of result ``r``; NaN where the run diverged (null fields)."""
    try:
        return float(get(r))
    except TypeError:  # a null (NaN or infinite) field
        return float("nan")


def row(label: str, values: list[float]) -> str:
    """One line of the table."""
    cells = [
        f"{v:8.0f}" if header == "fails" else f"{v:8.1f}" if abs(v) >= 10 else f"{v:8.3f}"
        for (header, _, _), v in zip(COLUMNS, values, strict=True)
    ]
    return f"{label:22s} " + " ".join(cells)


def print_table(problem: dict[str, Any], runs: dict[str, list[dict[str, Any]]]) -> None:
    """Every run, then the medians over the repeats per solver."""
    first = next(iter(runs.values()))[0]
    v, qp = first["versions"], first["qp"]
    print(
        f"TSID {v['tsid']} (pin {v['pin']}, eiquadprog {v['eiquadprog']}, python "
        f"{v['python']}) on TALOS standing: nv = {first['nv']}, na = {first['na']}, QP "
        f"{qp['n_var']} variables, {qp['n_eq']} equalities, {qp['n_in']} inequalities"
    )
    print(
        f"{problem['steps']} steps of {problem['dt']:g} s; CoM sine {problem['com_amplitude']:g}"
        f" m at {problem['com_frequency']:g} Hz along y; hands: {problem['hands']}; times "
        f"without the first {problem['warmup']} steps"
    )
    print(f"{'solver / repeat':22s} " + " ".join(f"{h:>8s}" for h, _, _ in COLUMNS))
    print(f"{'':22s} " + " ".join(f"{u:>8s}" for _, u, _ in COLUMNS))
    for solver, results in runs.items():
        for i, r in enumerate(results):
            print(row(f"{solver} #{i + 1}", [value(get, r) for _, _, get in COLUMNS]))
    for solver, results in runs.items():
        medians = [float(np.median([value(get, r) for r in results])) for _, _, get in COLUMNS]
        print(row(f"{solver} median", medians))
    note = (
        "solve: formulation.computeProblemData (compute) + solver.solve (qp), median, p10, "
        "p90 over the steps; step: also the reference update, getAccelerations and the "
        "integration; CoM: |com - com_ref| over the run, and its rms over the second half "
        "(2/2, after the start's transient); drift: the largest sole displacement at the end; "
        "CoP mrg: the smallest distance of a sole's centre of pressure to its edge; tau/max: "
        "the largest |tau| / tau_max; fails: steps whose QP failed; median rows: over the "
        "repeats"
    )
    print(textwrap.fill(note, 100))


def main() -> None:
    """Run the default problem ``--repeat`` times per solver and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--steps", type=int, default=None, help="default: the problem's")
    parser.add_argument(
        "--solvers",
        default="eiquadprog-fast",
        help=f"comma-separated, from {', '.join(SOLVERS)} (eiquadprog: about 7 ms a step)",
    )
    parser.add_argument("--hands", action="store_true", help="add the two hand tasks")
    parser.add_argument("--json", type=Path, help="also write every result to this file")
    args = parser.parse_args()
    solvers = args.solvers.split(",")
    bad = sorted(set(solvers) - set(SOLVERS))
    if bad:
        parser.error(f"unknown solvers {bad}: expected some of {', '.join(SOLVERS)}")
    changes: dict[str, Any] = {"hands": args.hands}
    if args.steps is not None:
        changes["steps"] = args.steps
    problem = default_problem(**changes)
    runs: dict[str, list[dict[str, Any]]] = {s: [] for s in solvers}
    try:
        for _ in range(args.repeat):
            for solver in solvers:  # interleaved: each repeat runs every solver once
                runs[solver].append(run_tsid({**problem, "solver": solver}))
    except TsidPeerError as exc:
        sys.exit(f"tsid_peer.py: {exc}")
    print_table(problem, runs)
    if args.json:
        args.json.write_text(json.dumps({"problem": problem, "runs": runs}, indent=1))


if __name__ == "__main__":
    main()
