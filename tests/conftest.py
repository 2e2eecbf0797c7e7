"""Shared fixtures: the bundled robots, loaded once per session."""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

import wholebody


@pytest.fixture(scope="session")
def humanoid() -> wholebody.Robot:
    return wholebody.load_robot("mobile_humanoid")


@pytest.fixture(scope="session")
def torso() -> wholebody.Robot:
    return wholebody.load_robot("dual_arm_torso")


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20241216)


# The compiled kernels' equivalence tests once more in a background process while the suite
# runs (the machine has two cores, the suite uses one): with NUMBA_DISABLE_JIT=1 (the
# kernels as plain Python: the code numba compiles is the code tested) and with
# NUMBA_BOUNDSCHECK=1 (an index out of bounds raises instead of corrupting memory; its own
# cache flavour, so it compiles everything once more: ~5 minutes). The session fails if they
# do. Started when the equivalence file is collected and slow tests are not deselected (after
# the warm-up below), and not under pytest-xdist (`-n`, for the fast subset: its workers
# take both cores), which says so at the end.
EQUIVALENCE = [
    "test_step.py",
    "test_torque_kernel.py",
    "test_contact_kernels.py",
    "test_dmp_kernels.py",
    "test_kernels.py",
    "test_daqp_kernel.py",
    "test_forward_kernel.py",
    "test_collision_kernel.py",
    "test_arm_energy_links.py",
]
_MODE = "WHOLEBODY_NUMBA_MODE"
_background: dict[str, object] = {}


def pytest_collection_finish(session: pytest.Session) -> None:
    config = session.config
    if (
        os.environ.get(_MODE)
        or os.environ.get("PYTEST_XDIST_WORKER")
        or config.option.collectonly
        or "not slow" in config.option.markexpr
    ):
        return
    if not any(item.path.name == "test_step.py" for item in session.items):
        return
    # The kernels compiled first, on both cores (`wholebody warmup`), instead of one by one
    # in the tests that first call them: a new environment's run is shorter by about a minute.
    from wholebody.warmup import warmup

    _background["warmup"] = warmup().seconds
    here = Path(__file__).parent
    files = " ".join(shlex.quote(str(here / f)) for f in EQUIVALENCE)
    pytest_cmd = f"{shlex.quote(sys.executable)} -m pytest -q -p no:cacheprovider {files}"
    script = f"NUMBA_DISABLE_JIT=1 {pytest_cmd} && NUMBA_BOUNDSCHECK=1 {pytest_cmd}"
    out = tempfile.TemporaryFile(mode="w+")  # noqa: SIM115 (closed in sessionfinish)
    proc = subprocess.Popen(
        ["bash", "-c", script],
        stdout=out,
        stderr=subprocess.STDOUT,
        env={**os.environ, _MODE: "1"},
        cwd=here.parent,
    )
    _background.update(proc=proc, out=out)


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    proc = _background.pop("proc", None)
    if proc is None:
        _say_if_skipped_under_xdist(session.config)
        return
    out = _background.pop("out")
    rc = proc.wait()
    out.seek(0)
    lines = out.read().splitlines()
    out.close()
    reporter = session.config.pluginmanager.get_plugin("terminalreporter")
    verdict = "passed" if rc == 0 else f"FAILED (exit {rc})"
    if reporter is not None:
        modes = "NUMBA_DISABLE_JIT=1 and NUMBA_BOUNDSCHECK=1"
        reporter.write_sep("=", f"kernels warmed up in {_background.pop('warmup'):.0f} s")
        reporter.write_sep("=", f"kernel equivalence with {modes}: {verdict}")
        for line in lines if rc else [s for s in lines if " passed" in s or " failed" in s]:
            reporter.write_line(line)
    if rc and session.exitstatus == 0:
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


def _say_if_skipped_under_xdist(config: pytest.Config) -> None:
    """Under ``-n`` the controller runs no test: say that the equivalence runs did not run."""
    if getattr(config.option, "numprocesses", None) and "not slow" not in config.option.markexpr:
        reporter = config.pluginmanager.get_plugin("terminalreporter")
        if reporter is not None:
            reporter.write("\n")
            reporter.write_sep(
                "=", "kernel equivalence: not run under -n (python -m pytest without -n runs it)"
            )
