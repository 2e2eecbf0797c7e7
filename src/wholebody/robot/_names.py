"""Name lookups that say what there is: an unknown name gets the closest known ones.

A robot is configured by names (joints, links, groups, arms) typed into ``robot.toml`` and
scripts; a typo should be answered with the name that was meant, not a bare ``KeyError``.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable, Mapping

__all__ = ["Named", "suggest"]


def suggest(name: object, candidates: Iterable[object]) -> str:
    """Up to three close matches, or the candidates themselves when none is close."""
    names = [str(c) for c in candidates]
    close = difflib.get_close_matches(str(name), names, n=3)
    if close:
        return f" (did you mean {', '.join(repr(c) for c in close)}?)"
    return f"; known: {', '.join(names)}" if names else ""


class Named(dict):
    """A dict of named parts (arms, groups) whose missing key says what there is."""

    def __init__(self, kind: str, items: Mapping[str, object]) -> None:
        super().__init__(items)
        self.kind = kind

    def __missing__(self, key: object) -> object:
        raise KeyError(f"no {self.kind} {key!r}" + suggest(key, self))
