"""The paper's experiments as scenario files: parsing, running, figures, comparisons."""

from __future__ import annotations

from wholebody.scenarios.runner import ScenarioRun, make_solver, run_scenario
from wholebody.scenarios.spec import ScenarioSpec, load_scenario

__all__ = ["ScenarioRun", "ScenarioSpec", "load_scenario", "make_solver", "run_scenario"]
