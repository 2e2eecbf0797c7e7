"""The period clock of a node's loop and the statistics its status reports.

:class:`Metronome` wakes at absolute deadlines ``t0 + k T`` (monotonic clock), so that
sleep errors do not accumulate. A period whose work ends after the next deadline **misses**
the deadlines it overran: they are counted and skipped (the loop goes on at the next
deadline still ahead), never made up by a burst of late commands. :meth:`Metronome.shift`
moves the deadlines a little (the node's phase lock onto the robot's states,
:func:`phase_error`).

:class:`Window` keeps the last ``size`` samples of a quantity (a step time, a latency) for
its percentiles.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

__all__ = ["Metronome", "Window", "phase_error"]


class Metronome:
    """Deadlines every ``period`` seconds from the first :meth:`wait` (module docstring).

    ``clock`` and ``sleep`` are the monotonic clock and the sleep (s); tests give their own.
    """

    def __init__(
        self,
        period: float,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        if not (math.isfinite(period) and period > 0):
            raise ValueError(f"period must be > 0 s, got {period!r}")
        self.period, self.clock, self.sleep = float(period), clock, sleep
        self.next: float | None = None
        self.missed = 0
        """Deadlines skipped because the work of a period overran them."""

    def shift(self, seconds: float) -> None:
        """Move the deadlines by ``seconds`` (at most a tenth of a period either way, so that
        the rate stays within 10 % for a period)."""
        if self.next is not None:
            limit = 0.1 * self.period
            self.next += min(max(seconds, -limit), limit)

    def wait(self) -> float:
        """Sleep until the next deadline and return it (s, the clock's); deadlines already
        passed are counted in :attr:`missed` and skipped."""
        now = self.clock()
        if self.next is None:
            self.next = now
            return now
        self.next += self.period
        if now > self.next:
            late = math.floor((now - self.next) / self.period) + 1
            self.missed += late
            self.next += late * self.period
        self.sleep(max(0.0, self.next - self.clock()))
        return self.next


def phase_error(arrived: float, deadline: float, period: float, lead: float) -> float:
    """How much later (s; negative: earlier) the deadline ``deadline`` should have been to
    come ``lead`` seconds after a state that ``arrived``, wrapped into ``[-T/2, T/2)``.

    The node's loop adds a fraction of it to its next deadline each period a new state
    arrives (a phase lock): its periods then start just after the robot's states instead of
    anywhere in the robot's period, which cuts the wait from a state to the command computed
    from it from ``T/2`` on average to about ``lead``, at the same rate."""
    e = (arrived + lead - deadline) % period
    return e - period if e >= period / 2 else e


class Window:
    """The last ``size`` samples of a quantity (module docstring)."""

    def __init__(self, size: int = 2000) -> None:
        self._data = np.zeros(int(size))
        self._n = 0

    def add(self, value: float) -> None:
        """Record one sample."""
        self._data[self._n % self._data.size] = value
        self._n += 1

    def __len__(self) -> int:
        return min(self._n, self._data.size)

    def percentiles(self, *q: float) -> list[float]:
        """The ``q``-th percentiles (0-100) of the samples kept; NaN without samples."""
        if not len(self):
            return [math.nan] * len(q)
        return np.percentile(self._data[: len(self)], q).tolist()

    def maximum(self) -> float:
        """The largest sample kept; NaN without samples."""
        return float(self._data[: len(self)].max()) if len(self) else math.nan
