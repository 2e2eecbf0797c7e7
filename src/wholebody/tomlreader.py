"""Reading TOML configuration files with errors that name the file, the key and what was
expected (robot.toml, scenario files)."""

from __future__ import annotations

import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from wholebody.errors import ConfigError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["TomlReader", "config_error", "load_toml"]


def config_error(path: Path, key: str, message: str) -> ConfigError:
    """The error for ``key`` of the file at ``path``: ``"<path>: [<key>] <message>"``."""
    return ConfigError(f"{path}: [{key}] {message}")


def load_toml(path: Path, what: str) -> dict[str, Any]:
    """Parse a TOML file; a :class:`ConfigError` naming the file if unreadable or invalid."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read {what} ({exc.strerror})") from exc
    except UnicodeDecodeError as exc:
        byte = exc.object[exc.start]
        raise ConfigError(
            f"{path}: {what} is not UTF-8 text (TOML must be): byte {byte:#04x} "
            f"at offset {exc.start}"
        ) from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from exc


class TomlReader:
    """Typed access to TOML tables with errors that name the file and the key."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def fail(self, key: str, message: str) -> ConfigError:
        return config_error(self.path, key, message)

    def table(self, data: Mapping[str, Any], key: str, where: str, required: bool) -> dict:
        full = f"{where}.{key}" if where else key
        if key not in data:
            if required:
                raise self.fail(full, "missing table: expected a TOML table here")
            return {}
        value = data[key]
        if not isinstance(value, dict):
            raise self.fail(full, f"expected a table, got {type(value).__name__}")
        return value

    def only(self, data: Mapping[str, Any], where: str, allowed: tuple[str, ...]) -> None:
        unknown = sorted(set(data) - set(allowed))
        if unknown:
            raise self.fail(
                f"{where}.{unknown[0]}" if where else unknown[0],
                f"unknown key; expected one of: {', '.join(allowed)}",
            )

    def string(
        self,
        data: Mapping[str, Any],
        key: str,
        where: str,
        default: str | None = None,
        choices: tuple[str, ...] | None = None,
    ) -> str:
        full = f"{where}.{key}"
        if key not in data:
            if default is None:
                raise self.fail(full, "missing key: expected a string")
            return default
        value = data[key]
        if not isinstance(value, str) or not value:
            raise self.fail(full, f"expected a non-empty string, got {value!r}")
        if choices is not None and value not in choices:
            raise self.fail(full, f"got {value!r}; expected one of: {', '.join(choices)}")
        return value

    def number(
        self,
        data: Mapping[str, Any],
        key: str,
        where: str,
        default: float | None = None,
        positive: bool = False,
    ) -> float:
        full = f"{where}.{key}"
        if key not in data:
            if default is None:
                raise self.fail(
                    full, "missing key: expected a number" + (" > 0" if positive else "")
                )
            return default
        value = data[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(full, f"expected a number, got {value!r}")
        if value != value or value in (float("inf"), float("-inf")):
            raise self.fail(full, f"expected a finite number, got {value!r}")
        if positive and value <= 0:
            raise self.fail(full, f"expected a number > 0, got {value!r}")
        return float(value)

    def names(
        self, data: Mapping[str, Any], key: str, where: str, count: int | None = None
    ) -> tuple[str, ...]:
        full = f"{where}.{key}" if where else key
        if key not in data:
            raise self.fail(full, "missing key: expected a list of joint names")
        value = data[key]
        if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
            raise self.fail(full, f"expected a list of non-empty strings, got {value!r}")
        if count is not None and len(value) != count:
            raise self.fail(full, f"expected exactly {count} names, got {len(value)}")
        duplicates = sorted({v for v in value if value.count(v) > 1})
        if duplicates:
            raise self.fail(full, f"names listed twice: {', '.join(duplicates)}")
        return tuple(value)

    def vector(
        self,
        data: Mapping[str, Any],
        key: str,
        where: str,
        size: int,
        default: tuple[float, ...] | None = None,
    ) -> tuple[float, ...]:
        """A list of ``size`` finite numbers."""
        full = f"{where}.{key}"
        if key not in data:
            if default is None:
                raise self.fail(full, f"missing key: expected a list of {size} numbers")
            return default
        value = data[key]
        if (
            not isinstance(value, list)
            or len(value) != size
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
        ):
            raise self.fail(full, f"expected a list of {size} numbers, got {value!r}")
        if not all(v == v and abs(v) != float("inf") for v in value):
            raise self.fail(full, f"expected finite numbers, got {value!r}")
        return tuple(float(v) for v in value)

    def boolean(self, data: Mapping[str, Any], key: str, where: str, default: bool) -> bool:
        """A true/false value."""
        if key not in data:
            return default
        value = data[key]
        if not isinstance(value, bool):
            raise self.fail(f"{where}.{key}", f"expected true or false, got {value!r}")
        return value
