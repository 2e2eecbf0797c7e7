"""The hyper-parameters of a DMP: stiffness, damping, the phase's time constant and the basis
functions' layout.

**Phase and convergence (decision).** With the phase on ``tau = T`` it would end at
``s(T) = exp(-alpha_s) = 0.018`` (``alpha_s = 4``), and a moved goal would be missed by about
1.8 % of the shift (the goal-shift term ``K (g - x0) s`` has not died out: 3.6 mm for a
20 cm shift). Here the phase runs on its own time constant, chosen so that it reaches
``phase_end`` (default ``1e-4``) at ``t = T``::

    tau_s = alpha_s T / ln(1 / phase_end)          (= 0.434 T with the defaults)

``alpha_s`` keeps its value and the transformation system keeps ``tau = T``, so ``K`` means
what it means in the paper (stiffness per movement duration). The residual goal error is
``phase_end`` times the goal shift plus the lag of the critically damped system at the end,
``2 sqrt(K)^-1 ln(1/phase_end) phase_end`` times the shift: 0.03 mm for a 20 cm shift.

**Basis layout.** ``n`` Gaussians ``psi_i(s) = exp(-h_i (s - c_i)^2)`` with centres evenly
spaced in time, ``c_i = phase_end^(i / (n - 1))``, and widths from the spacing, so that
neighbours cross at the height ``overlap``: ``h_i = 4 ln(1 / overlap) / (c_i - c_{i+1})^2``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from wholebody.errors import DimensionError
from wholebody.planning._checks import as_positive

__all__ = ["DMPConfig"]


@dataclass(frozen=True)
class DMPConfig:
    """Hyper-parameters of a DMP (module docstring).

    Attributes
    ----------
    n_basis
        Number of Gaussian basis functions (>= 2).
    stiffness
        ``K`` (dimensionless, per unit ``tau``), > 0.
    damping
        ``D``; ``None`` means ``2 sqrt(K)`` (critical damping).
    alpha_s
        Phase decay rate, > 0.
    phase_end
        Phase value at the end of the movement, in (0, 1): fixes the phase's time constant
        ``tau_s / T`` (module docstring).
    overlap
        Height, in (0, 1), at which neighbouring basis functions cross. Wide, strongly
        overlapping Gaussians (0.9) let the normalised basis follow the steep start of the
        forcing target (where ``(g - x0) s`` falls fastest) without ripple.
    """

    n_basis: int = 50
    stiffness: float = 1050.0
    damping: float | None = None
    alpha_s: float = 4.0
    phase_end: float = 1e-4
    overlap: float = 0.9

    def __post_init__(self) -> None:
        if int(self.n_basis) != self.n_basis or self.n_basis < 2:
            raise DimensionError(f"DMPConfig: n_basis must be an integer >= 2, got {self.n_basis}")
        as_positive(self.stiffness, "DMPConfig: stiffness")
        if self.damping is not None:
            as_positive(self.damping, "DMPConfig: damping")
        as_positive(self.alpha_s, "DMPConfig: alpha_s")
        if not 0.0 < float(self.phase_end) < 1.0:
            raise DimensionError(f"DMPConfig: phase_end must be in (0, 1), got {self.phase_end}")
        if not 0.0 < float(self.overlap) < 1.0:
            raise DimensionError(f"DMPConfig: overlap must be in (0, 1), got {self.overlap}")

    @property
    def K(self) -> float:
        """Stiffness ``K``."""
        return float(self.stiffness)

    @property
    def D(self) -> float:
        """Damping ``D`` (``2 sqrt(K)`` unless set)."""
        return 2.0 * math.sqrt(self.K) if self.damping is None else float(self.damping)

    @property
    def phase_tau_ratio(self) -> float:
        """``tau_s / T = alpha_s / ln(1 / phase_end)``: the phase's time constant per unit
        duration."""
        return float(self.alpha_s) / math.log(1.0 / float(self.phase_end))

    def centers(self) -> np.ndarray:
        """Basis centres ``c_i = phase_end^(i / (n - 1))``: evenly spaced in time on [0, T]."""
        return self.layout()[0].copy()

    def widths(self) -> np.ndarray:
        """``h_i = 4 ln(1 / overlap) / (c_i - c_{i+1})^2`` (the last reuses the previous gap):
        neighbouring basis functions cross at height ``overlap``."""
        return self.layout()[1].copy()

    def layout(self) -> tuple[np.ndarray, np.ndarray]:
        """``(centers, widths)``, read-only and shared by every DMP of this configuration."""
        return _basis_layout(int(self.n_basis), float(self.phase_end), float(self.overlap))


@lru_cache(maxsize=32)
def _basis_layout(n: int, phase_end: float, overlap: float) -> tuple[np.ndarray, np.ndarray]:
    """Centres and widths of :class:`DMPConfig` (read-only, cached: every DMP built from one
    configuration shares them)."""
    c = phase_end ** np.linspace(0.0, 1.0, n)
    gap = np.abs(np.diff(c))
    gap = np.append(gap, gap[-1])
    h = 4.0 * math.log(1.0 / overlap) / gap**2
    c.setflags(write=False)
    h.setflags(write=False)
    return c, h
