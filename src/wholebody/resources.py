"""Where the robots and scenario files that ship with wholebody live, and file naming.

In a wheel they are package data under ``wholebody/_share/``; in a source checkout they are
the repository's ``robots/``, ``tasks/`` and ``data/`` directories.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["bundled_file", "data_dir", "npz_path", "robots_dir", "share_dir", "tasks_dir"]


def share_dir() -> Path:
    """The directory holding ``robots/`` and ``tasks/``."""
    installed = Path(__file__).resolve().parent / "_share"
    if (installed / "robots").is_dir():
        return installed
    return Path(__file__).resolve().parents[2]


def robots_dir() -> Path:
    """The bundled robot descriptions: one directory per robot with a ``robot.toml``."""
    return share_dir() / "robots"


def tasks_dir() -> Path:
    """The bundled scenario files (the paper's experiments)."""
    return share_dir() / "tasks"


def bundled_file(name: str, folder: Path) -> Path | None:
    """The TOML file ``name`` (with or without ``.toml``) in ``folder``, or None."""
    path = folder / (name if name.endswith(".toml") else f"{name}.toml")
    return path if path.is_file() else None


def data_dir() -> Path:
    """The bundled data sets (human reaching recordings, with their licences)."""
    return share_dir() / "data"


def npz_path(path: str | Path) -> Path:
    """``path`` with ``.npz`` appended unless it ends so: the file ``np.savez`` writes."""
    path = Path(path)
    return path if path.suffix == ".npz" else path.with_name(path.name + ".npz")
