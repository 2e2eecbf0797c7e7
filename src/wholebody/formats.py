"""File format versions: which semantics a scenario, campaign or ``robot.toml`` was written for.

Each of these files says it with one top-level key, before its first table::

    format = 2          # a scenario; campaigns and robot.toml are at format 1

A file's keys keep their names when their meaning changes (a scenario's missing ``start``
meant the neutral posture before format 2 and means home since), so a file read with the
wrong semantics runs and does something else: the coordinated carry written for neutral
starts at home and its carry misses by 345 mm, and nothing says why. The number makes the
change loud: a file without the key, or with an older number, is refused with what changed
and what to edit; a newer number is refused as written for a newer wholebody. The current
numbers and the history of each kind are here, in one place; the readers
(:mod:`wholebody.scenarios.spec`, :mod:`wholebody.sweep.campaign`,
:mod:`wholebody.robot.config`) call :func:`check_format` first, and whatever writes one of
these files writes :attr:`FileFormat.line`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from wholebody.errors import ConfigError
from wholebody.tomlreader import TomlReader

__all__ = ["CAMPAIGN", "FORMAT_KEY", "ROBOT", "SCENARIO", "FileFormat", "check_format"]

FORMAT_KEY = "format"
"""The top-level key that holds a file's format number."""


@dataclass(frozen=True)
class FileFormat:
    """The format history of one kind of file.

    ``changes[v]`` says what format ``v`` changed against format ``v - 1`` and what to edit
    in a file written for the older one (``v`` from ``unnumbered + 1`` to ``current``); a file
    without the key is read as format ``unnumbered`` (the one before the first numbered
    format, or the first one if it had no key)."""

    kind: str
    """The files' name in messages ("scenario", "campaign", "robot.toml")."""
    current: int
    """The format this wholebody reads and writes."""
    unnumbered: int
    """The format a file without the key was written for."""
    changes: Mapping[int, str]

    @property
    def line(self) -> str:
        """The key as a writer puts it at the top of a file: ``format = 2``."""
        return f"{FORMAT_KEY} = {self.current}"

    def upgrade(self, version: int) -> str:
        """What changed since ``version`` and what to edit, ending with the key to add."""
        steps = [f"format {v}: {self.changes[v]}" for v in range(version + 1, self.current + 1)]
        return "; ".join(steps) + (
            f". Then put `{self.line}` at the top of the file, before its first table"
        )


SCENARIO = FileFormat(
    "scenario",
    current=2,
    unnumbered=1,
    changes={
        2: "`[scenario] start` now defaults to home (the robot's [home] posture of its "
        "robot.toml; format 1 started every run at neutral, all joints at 0); goals and "
        '`rotate` values computed from the neutral posture need `start = "neutral"` in '
        "[scenario] (a file that already sets `start` means what it says)",
    },
)
"""Scenario files (:mod:`wholebody.scenarios.spec`); format 1 had no key."""

CAMPAIGN = FileFormat(
    "campaign",
    current=1,
    unnumbered=0,
    changes={
        1: "the first numbered campaign format, the keys mean what they meant before "
        "(nothing else to edit; its base scenario file has a format of its own)",
    },
)
"""Campaign files (:mod:`wholebody.sweep.campaign`)."""

ROBOT = FileFormat(
    "robot.toml",
    current=1,
    unnumbered=0,
    changes={
        1: "the first numbered robot.toml format, the keys mean what they meant before "
        "(nothing else to edit)",
    },
)
"""``robot.toml`` files (:mod:`wholebody.robot.config`)."""


def check_format(r: TomlReader, data: Mapping[str, Any], fmt: FileFormat) -> None:
    """Refuse a file (parsed TOML ``data``, named by ``r``) not written for ``fmt.current``.

    Raises
    ------
    ConfigError
        ``"<path>: [format] ..."``: the key missing or older (what changed since and what to
        edit), newer (written for a newer wholebody), or not a whole number.
    """
    if FORMAT_KEY not in data:
        written = (
            f"format {fmt.unnumbered}, which had no key"
            if fmt.unnumbered
            else "before the formats were numbered"
        )
        raise _fail(
            r,
            f"missing key: a {fmt.kind} file without it was written for {written}; "
            f"this wholebody reads format {fmt.current}. What changed since: "
            f"{fmt.upgrade(fmt.unnumbered)}",
        )
    version = data[FORMAT_KEY]
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise _fail(
            r,
            f"expected the {fmt.kind} format as a whole number >= 1 (`{fmt.line}`), "
            f"got {version!r}",
        )
    if version > fmt.current:
        raise _fail(
            r,
            f"format = {version}: written for a newer wholebody (this one reads "
            f"{fmt.kind} format {fmt.current}); update wholebody",
        )
    if version < fmt.current:
        raise _fail(
            r,
            f"format = {version}: written for format {version}; this wholebody "
            f"reads format {fmt.current}. What changed since: "
            f"{fmt.upgrade(version)}",
        )


def _fail(r: TomlReader, message: str) -> ConfigError:
    return r.fail(FORMAT_KEY, message)
