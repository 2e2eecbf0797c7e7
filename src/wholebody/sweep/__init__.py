"""Sweeps: many runs of a scenario with keys varied, on all local cores or on a Ray cluster.

``wholebody sweep CAMPAIGN --out DIR [--workers N] [--ray [ADDRESS]] [--timeout S]`` (or
:func:`run_sweep`) reads a campaign file (:mod:`wholebody.sweep.campaign`), runs every case
not yet in ``DIR`` (:mod:`wholebody.sweep.store`) with the same function locally or on Ray
(:mod:`wholebody.sweep.executors`), writes each result as soon as it comes back, then
``results.csv``, the best cases and the plots (:mod:`wholebody.sweep.report`).
"""

from __future__ import annotations

import math
import os
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

from wholebody.errors import ConfigError
from wholebody.sweep.campaign import Axis, Campaign, Case, load_campaign
from wholebody.sweep.case import run_case
from wholebody.sweep.store import SweepStore

__all__ = ["Axis", "Campaign", "Case", "SweepResult", "load_campaign", "run_case", "run_sweep"]


@dataclass
class SweepResult:
    """What :func:`run_sweep` did: the cases in the campaign, those found finished in the
    directory, those run now and how many of all failed; the table and report files."""

    cases: int
    found: int
    ran: int
    failed: int
    wall_time: float
    files: dict[str, Path]
    rows: list[dict]


def run_sweep(
    campaign: Campaign,
    out: str | Path,
    *,
    workers: int | None = None,
    ray: bool = False,
    address: str | None = None,
    retry_failed: bool = False,
    progress: bool = True,
    ray_public: bool = False,
    timeout: float | None = None,
) -> SweepResult:
    """Run the campaign's missing cases into ``out``: on ``workers`` local processes
    (default: every core) or, with ``ray``, as Ray tasks (``address`` of a cluster, or a
    local instance on the loopback interface only, unless ``ray_public``: see
    :func:`wholebody.sweep.executors.start_local_ray`). A case running longer than
    ``timeout`` s of wall time is stopped and recorded as ``"timeout"``. Results are written
    one file per case as each ends; on Ctrl-C the table and report of the finished cases are
    written before the interrupt goes on.

    The kernels are compiled (or loaded) here first (:func:`wholebody.warmup.warmup`), into
    the cache every worker on this machine reads: the workers load them instead of each
    compiling them at once. A cluster's other nodes use their own installation's cache
    (``wholebody warmup`` on each, or ``NUMBA_CACHE_DIR`` on a shared disk)."""
    from wholebody.sweep.executors import run_local, run_ray
    from wholebody.sweep.report import write_report

    if timeout is not None and not 0 < timeout < math.inf:
        raise ConfigError(f"a case's time limit must be > 0 s and finite, got {timeout}")
    store = SweepStore(Path(out), campaign)
    cases = campaign.cases()
    results = store.finished(cases, retry_failed)
    found = len(results)
    # draw-major: an interrupted sweep has every grid point on the same draws so far
    todo = sorted((c for c in cases if c.index not in results), key=lambda c: (c.sample, c.index))
    bar = _Progress(len(cases), found, campaign.name, progress)
    bar.failed = sum(r["status"] != "ok" for r in results.values())
    start = last_table = time.perf_counter()

    def on_result(result: dict) -> None:
        nonlocal last_table
        store.write(result)
        results[result["index"]] = result
        bar.update(result["status"] != "ok")
        if time.perf_counter() - last_table > TABLE_EVERY:  # inspectable while it runs
            store.table(results)
            last_table = time.perf_counter()

    if todo:  # compiled (or loaded) once here: the workers then load the shared cache
        from wholebody.warmup import warmup

        warmup()
    try:
        if ray:
            run_ray(campaign, todo, address, on_result, workers, ray_public, timeout)
        else:
            run_local(campaign, todo, workers or _cores(), on_result, timeout)
    finally:
        bar.close()
        table, rows = store.table(results)
        files = {"table": table}
        try:
            files.update(write_report(campaign, rows, store.out))
        except Exception as exc:  # a plot must not hide the sweep's outcome
            warnings.warn(f"the sweep's report was not written: {exc}", stacklevel=2)
    return SweepResult(
        len(cases),
        found,
        bar.done - found,
        sum(r["status"] != "ok" for r in rows),
        time.perf_counter() - start,
        files,
        rows,
    )


TABLE_EVERY = 60.0
"""Seconds between rebuilds of ``results.csv`` while a sweep runs."""


def _cores() -> int:
    """The cores this process may run on (its affinity, not the machine's count)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


class _Progress:
    """Cases done and failed, and the time left: a tqdm bar on a terminal, a plain line
    every 10 s elsewhere (a log keeps a bar's carriage returns as one growing line)."""

    def __init__(self, total: int, done: int, name: str, enabled: bool) -> None:
        self.total, self.done, self.failed = total, done, 0
        self.start_done, self.name, self.enabled = done, name, enabled
        self.start = self.last = time.perf_counter()
        self.bar = None
        if enabled and sys.stderr.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=total, initial=done, unit="case", desc=f"sweep {name}")

    def update(self, failed: bool) -> None:
        self.done += 1
        self.failed += failed
        if self.bar is not None:
            self.bar.set_postfix_str(f"{self.failed} failed")
            self.bar.update(1)
        elif self.enabled and time.perf_counter() - self.last >= 10.0:
            self.last = time.perf_counter()
            print(self.line(), file=sys.stderr, flush=True)

    def line(self) -> str:
        elapsed = time.perf_counter() - self.start
        ran = self.done - self.start_done
        if self.done >= self.total:
            left = "done"
        elif ran:
            left = f"about {(self.total - self.done) * elapsed / ran:.0f} s left"
        else:
            left = "time left not known yet"
        return (
            f"sweep {self.name}: {self.done}/{self.total} cases, {self.failed} failed, "
            f"{elapsed:.0f} s, {left}"
        )

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
        elif self.enabled:
            print(self.line(), file=sys.stderr, flush=True)
