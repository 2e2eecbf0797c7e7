"""Every bundled scenario with each backend: the solver failures (steps where a task that
could have been met was not), the steps with a task unmet by cause, and where each hand
ends against its goal (mm, rad).

    python benchmarks/unmet_steps.py [SCENARIO ...]

A scenario whose robot is not installed (``pip install '.[robots]'``) is skipped with the
reason. Kinematic runs; about 30 s on this machine once the kernels are compiled.
"""

from __future__ import annotations

import json
import sys
import time

from wholebody.errors import WholebodyError
from wholebody.resources import tasks_dir
from wholebody.scenarios import load_scenario, run_scenario

BACKENDS = ("pinv", "projection", "hqp")


def main(names: list[str]) -> None:
    names = names or sorted(p.stem for p in tasks_dir().glob("*.toml"))
    for name in names:
        spec = load_scenario(tasks_dir() / f"{name}.toml")
        for backend in BACKENDS:
            start = time.perf_counter()
            try:
                run = run_scenario(spec, backend=backend)
            except WholebodyError as exc:  # a robot that is not installed
                print(f"{name:24s} {backend:10s} skipped: {exc}", flush=True)
                continue
            m = run.metrics
            ends = {
                h: f"{e['position_m'] * 1e3:.2f} mm"
                + ("" if e["rotation_rad"] is None else f" / {e['rotation_rad']:.4f} rad")
                for h, e in m["final_error"].items()
            }
            print(
                f"{name:24s} {backend:10s} steps {len(run.log):5d} failures "
                f"{m['solver_failures']:4d} unmet {json.dumps(m['unmet_steps'])} ends {ends} "
                f"[{time.perf_counter() - start:.0f} s]",
                flush=True,
            )


if __name__ == "__main__":
    main(sys.argv[1:])
