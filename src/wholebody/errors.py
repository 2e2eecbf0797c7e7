"""The exception hierarchy of wholebody.

Every error raised on bad input is a :class:`WholebodyError` subclass whose message names
the file, key, task or level at fault and what was expected, so that a user never has to
read a traceback from deep inside Pinocchio or numpy to find the mistake.
"""

from __future__ import annotations


class WholebodyError(Exception):
    """Base class of every error raised by wholebody on bad input or failed operations."""


class ConfigError(WholebodyError):
    """A configuration file (robot.toml, scenario file) is malformed or inconsistent."""


class ModelError(WholebodyError):
    """A robot description (URDF) cannot be loaded or does not match its configuration."""


class FrameError(WholebodyError, KeyError):
    """An unknown frame, body, joint or group name was requested."""

    def __str__(self) -> str:  # KeyError quotes its message; keep it readable
        return str(self.args[0]) if self.args else ""


class DimensionError(WholebodyError, ValueError):
    """An array argument has the wrong shape or contains non-finite values."""


class DataError(WholebodyError, ValueError):
    """A data file (recordings, dataset, weights) is malformed."""


class IntegrationError(WholebodyError, ArithmeticError):
    """A numerical integration could not meet its error tolerance."""


class SolverError(WholebodyError):
    """A solver could not be set up (unknown engine, missing optional dependency)."""
