"""Files written whole or not at all, and ``.npz`` files read with errors that name them.

Every file wholebody writes (run logs, metrics, figures, datasets, networks, recordings,
comparison tables) goes to a temporary file in the same directory, is flushed to disk and
then renamed over the target (``os.replace``, atomic on POSIX and Windows): a crash, a full
disk or Ctrl-C mid-write leaves the previous file as it was, never a truncated one.

``.npz`` files are read eagerly with ``allow_pickle=False``: a missing, empty, truncated or
corrupt file raises :class:`~wholebody.errors.DataError` naming the file and what it should
have been, never a raw ``zipfile.BadZipFile``, ``EOFError`` or ``zlib.error``.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
import zipfile
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

import numpy as np

from wholebody.errors import DataError

__all__ = ["atomic_path", "read_npz", "save_figure", "write_json", "write_npz", "write_text"]

_READ_ERRORS = (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error, KeyError)


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path beside ``path`` (same suffix) to write to; renamed onto ``path``
    when the block ends without an exception, removed otherwise. Parent directories are
    created."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=path.suffix)
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        with tmp.open("rb+") as fh:  # on disk before the rename makes it the file
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


@contextlib.contextmanager
def _atomic_file(path: str | Path, mode: str) -> Iterator[IO[Any]]:
    with atomic_path(path) as tmp, tmp.open(mode) as fh:
        yield fh


def write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) atomically; returns ``path``."""
    with _atomic_file(path, "w") as fh:
        fh.write(text)
    return Path(path)


def write_json(path: str | Path, data: object, **dumps: Any) -> Path:
    """Write ``json.dumps(data, **dumps)`` atomically (serialised before the file is
    touched, so an unserialisable value leaves the old file)."""
    return write_text(path, json.dumps(data, **dumps))


def write_npz(path: str | Path, arrays: dict[str, np.ndarray], *, compress: bool = True) -> Path:
    """Write ``arrays`` as an ``.npz`` at exactly ``path``, atomically; returns ``path``."""
    save = np.savez_compressed if compress else np.savez
    with _atomic_file(path, "wb") as fh:
        save(fh, **arrays)
    return Path(path)


def save_figure(fig: Any, path: str | Path, **savefig: Any) -> Path:
    """``fig.savefig`` atomically (the format from ``path``'s suffix); returns ``path``."""
    path = Path(path)
    fmt = path.suffix.lstrip(".") or None
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format=fmt, **savefig)
    return path


def read_npz(path: str | Path, what: str) -> dict[str, np.ndarray]:
    """Every array of the ``.npz`` at ``path`` (no pickle), or :class:`DataError`
    ``"<path>: not a readable <what> (...)"``."""
    path = Path(path)
    try:
        with path.open("rb") as fh:
            head = fh.read(6)
            if head and not head.startswith((b"PK\x03\x04", b"PK\x05\x06", b"\x93NUMPY")):
                raise ValueError("not an .npz archive: no zip header")
            fh.seek(0)
            z = np.load(fh, allow_pickle=False)
            if not isinstance(z, np.lib.npyio.NpzFile):
                raise ValueError("a single .npy array, not an .npz archive")
            with z:
                return {k: z[k] for k in z.files}
    except _READ_ERRORS as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
        if isinstance(exc, (EOFError, zipfile.BadZipFile, zlib.error)) or not str(reason):
            reason = f"empty, truncated or corrupt .npz: {type(exc).__name__} {exc}".strip()
        raise DataError(f"{path}: not a readable {what} ({reason})") from None
