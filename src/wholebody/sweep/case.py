"""One case of a sweep, as a worker runs it: the case's scenario run like ``wholebody run``.

:func:`run_case` is a plain top-level function of picklable arguments, so that a process
pool and Ray run the same code. It never raises: a case that fails returns its error (type,
message and the traceback's last lines), a case that runs longer than the sweep's time limit
is stopped and returns ``"timeout"`` (a timer of the worker's main thread, :class:`_Limit`:
the run stops at its next Python step, a control step being microseconds to milliseconds),
and the sweep goes on.
"""

from __future__ import annotations

import json
import math
import signal
import threading
import time
import traceback
from typing import Any

import numpy as np

from wholebody import kernels
from wholebody.control.log import json_default
from wholebody.sweep.campaign import Campaign, Case

__all__ = ["CaseTimeoutError", "headline", "run_case"]


def headline(run) -> dict[str, float]:
    """One number each, over the hands: ``tracking_error_max_m`` (the largest distance of a
    hand to its reference, m), ``mae_max_m`` (the largest per-axis mean absolute error, m),
    ``final_error_m`` (the largest distance at the last step, m)."""
    log, m = run.log, run.metrics
    final = [
        float(np.linalg.norm(log.frame_positions[h][-1] - log.reference_positions[h][-1]))
        for h in log.frame_positions
        if np.isfinite(log.reference_positions[h][-1]).all()
    ]
    mae = [v for axes in m["mae_m"].values() for v in axes.values()]
    return {
        "tracking_error_max_m": _worst(m["max_tracking_error_m"].values()),
        "mae_max_m": _worst(mae),
        "final_error_m": _worst(final),
    }


def _worst(values) -> float:
    """The largest value; NaN if any is NaN or there is none (never a best case)."""
    values = np.asarray(list(values), dtype=float)
    return float(values.max()) if values.size and not np.isnan(values).any() else math.nan


class CaseTimeoutError(BaseException):
    """A case ran longer than the sweep's time limit (raised by :class:`_Limit`'s timer; a
    ``BaseException``, as ``KeyboardInterrupt``, so that no handler of errors in the run
    swallows it)."""


_RETRY = 0.02  # s: how soon a time limit that fell inside a kernel's loading tries again


class _Limit:
    """A wall-time limit on this thread: :meth:`start` arms a real-time interval timer whose
    signal raises :class:`CaseTimeoutError` (Unix, main thread: a worker's; elsewhere, or with
    ``seconds`` None, nothing is armed); :meth:`stop` disarms it and gives the signal back its
    handler, and may be called again. The handler raises only while armed, so a signal that
    lands after :meth:`stop` began is ignored, and never while numba loads or compiles a
    kernel (:func:`wholebody.kernels.compiling`): it tries again every ``_RETRY`` s."""

    def __init__(self, seconds: float | None) -> None:
        self.seconds = seconds
        self.armed = self._installed = self.expired = False
        self._previous: Any = None

    def start(self) -> None:
        usable = (
            hasattr(signal, "setitimer") and threading.current_thread() is threading.main_thread()
        )
        if self.seconds is None or not usable:
            return
        self._previous = signal.signal(signal.SIGALRM, self._expire)
        self._installed = self.armed = True
        signal.setitimer(signal.ITIMER_REAL, self.seconds)

    def _expire(self, signum: int, frame: object) -> None:
        if not self.armed:
            return
        if kernels.compiling():  # a kernel half loaded would break the worker's later cases:
            signal.setitimer(signal.ITIMER_REAL, _RETRY)  # raise once it is loaded
            return
        self.armed, self.expired = False, True
        raise CaseTimeoutError(f"ran longer than the time limit of {self.seconds:g} s (--timeout)")

    def stop(self) -> None:
        self.armed = False
        if self._installed:
            signal.setitimer(signal.ITIMER_REAL, 0.0)
            previous = self._previous
            signal.signal(signal.SIGALRM, signal.SIG_DFL if previous is None else previous)
            self._installed = False


def run_case(campaign: Campaign, case: Case, timeout: float | None = None) -> dict[str, Any]:
    """Run one case; its result: ``index``, ``values``, ``status`` (``"ok"``, ``"error"``,
    ``"timeout"``: it ran longer than ``timeout`` seconds of wall time, or ``"stopped"``: a
    physics run ended early, its reason in ``error``), ``metrics`` (those of ``wholebody
    run``'s ``metrics.json`` and the :func:`headline` numbers), ``error`` and ``wall_s``."""
    from wholebody.scenarios.runner import run_scenario

    start = time.perf_counter()
    result: dict[str, Any] = {"index": case.index, "values": case.values}
    limit = _Limit(timeout)
    try:
        limit.start()
        spec, options = campaign.case_spec(case)
        run = run_scenario(
            spec,
            backend=options.get("backend"),
            sim=options["sim"],
            engine=options.get("engine"),
            duration_scale=campaign.duration_scale,
        )
        limit.stop()
        if limit.expired:  # the timeout, swallowed by code it crossed: the run went on
            raise CaseTimeoutError(f"ran longer than the time limit of {timeout:g} s (--timeout)")
        metrics = json.loads(json.dumps(run.metrics, default=json_default))
        metrics.update(headline(run))
        stopped = metrics.get("stopped")  # a physics run the plant ended early
        result.update(status="stopped" if stopped else "ok", metrics=metrics, error=stopped or "")
    except CaseTimeoutError as exc:
        result.update(status="timeout", metrics={}, error=str(exc))
    except Exception as exc:  # recorded, not raised: the sweep goes on
        limit.stop()
        tail = "\n".join(traceback.format_exc().strip().splitlines()[-6:])
        error = f"{type(exc).__name__}: {exc}"
        if limit.expired:  # the timeout, turned into another error by code it crossed
            error = f"ran longer than the time limit of {timeout:g} s (--timeout): {error}"
        result.update(
            status="timeout" if limit.expired else "error", metrics={}, error=error, traceback=tail
        )
    finally:
        limit.stop()
    result["wall_s"] = time.perf_counter() - start
    return result
