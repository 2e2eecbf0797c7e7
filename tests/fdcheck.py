"""Finite-difference references shared by the tests: those of :mod:`wholebody.testing`."""

from __future__ import annotations

from wholebody.testing import frame_jacobian_fd, gradient_fd, jacobian_fd

__all__ = ["frame_jacobian_fd", "gradient_fd", "jacobian_fd"]
