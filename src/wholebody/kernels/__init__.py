"""The compiled core: numba kernels for the control step and the DMP rollout.

A kernel is plain numpy-style Python under :func:`kernel` (``numba.njit(cache=True)``), so
``NUMBA_DISABLE_JIT=1`` runs exactly the same code uncompiled: the tests compare both, and
once more with ``NUMBA_BOUNDSCHECK=1``. Kernels take numpy arrays and numbers only; the
Python side (:mod:`wholebody.solvers.plan`, :mod:`wholebody.planning.dmp`) lays out their
buffers once and calls them.

Compilation happens once per machine. On first use a kernel is compiled (tens of seconds
for the whole control core; :func:`compile_notice` tells the user) and written to a cache;
later processes load it in well under a second. ``wholebody warmup`` compiles everything
ahead of time. The cache lives in the package's ``__pycache__`` directories or, when the
installed package is not writable, in the user's cache directory
(``$XDG_CACHE_HOME/numba`` or ``~/.cache/numba``); ``NUMBA_CACHE_DIR`` overrides both. A
kernel's cache entry is keyed on a digest of its module's source and of the kernel modules
that module imports (numba alone would only notice a change of the caller's own file, and
reuse a caller compiled against an older callee), and kept apart for
``NUMBA_BOUNDSCHECK=1`` builds.

**Compile time.** numba compiles each kernel into a library of machine code that holds the
kernel and, linked in, everything it calls; every library along a call chain runs LLVM's full
optimisation over its whole subtree, so the deepest code is optimised once per level above
it. Here a kernel compiled *for another kernel* (not called from Python) gets only LLVM's
cheap inlining pass: the kernel Python calls optimises the whole, once. Measured on the
projection's control step (2 cores): first compile 102 s -> 53 s, the step as fast. The
machine code of such a callee, if Python later calls it directly, is less optimised (the
control step never does). numba's internals involved are those of numba 0.60 to 0.68
(``CPUCodeLibrary._optimize_final_module``); elsewhere everything is optimised, as numba
does.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import re
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TypeVar

import numba
from numba.core import caching, codegen, types

__all__ = ["DISABLED", "as_callees", "cache_directory", "compile_notice", "compiling", "kernel"]

F = TypeVar("F", bound=Callable)

DISABLED: bool = bool(numba.config.DISABLE_JIT)
"""Whether kernels run uncompiled (``NUMBA_DISABLE_JIT=1``)."""

_HERE = Path(__file__).resolve().parent


_IMPORT = re.compile(r"^\s*from wholebody\.kernels(\.\w+)? import (\([^)]*\)|[^\n]*)", re.M)


@functools.cache
def _imports(name: str) -> frozenset[str]:
    """The kernel modules the kernel module ``name`` imports (``from wholebody.kernels[.x]
    import ...``; read as text: parsing every module's syntax tree took a second of the
    package's import)."""
    names = set()
    for module, items in _IMPORT.findall((_HERE / name).read_text(encoding="utf-8")):
        if module:
            names.add(module[1:] + ".py")
        else:
            for item in items.strip("()").replace("\n", " ").split(","):
                if item.strip():
                    names.add(item.split()[0] + ".py")
    return frozenset(n for n in names if (_HERE / n).is_file())


@functools.cache
def _digest(name: str) -> str:
    """A digest of the source of the kernel module ``name`` and of every kernel module it
    depends on (its imports, transitively) and of this one: the cache's freshness stamp."""
    todo, seen = [name, "__init__.py"], set()
    while todo:
        n = todo.pop()
        if n not in seen:
            seen.add(n)
            todo.extend(_imports(n))
    h = hashlib.sha256()
    for n in sorted(seen):
        h.update(n.encode())
        h.update((_HERE / n).read_bytes())
    return h.hexdigest()


def _flavour() -> str:
    """The cache subdirectory for the current compile flags."""
    return "boundscheck" if numba.config.BOUNDSCHECK else "default"


class _KernelCacheLocator(caching._CacheLocator):
    """Where numba caches a kernel of this package (see the module docstring): the user's
    ``NUMBA_CACHE_DIR``, else the package's ``__pycache__``, else the user-wide cache; the
    freshness stamp is the digest of the kernel's module and of the kernel modules it
    depends on, and is part of the entry's file name, so that an entry written for other
    sources is never opened."""

    def __init__(self, py_func: Callable, py_file: str, path: str) -> None:
        self._lineno = py_func.__code__.co_firstlineno
        self._py_file = py_file  # (numba reads it to warn about what it cannot cache)
        self._stamp = _digest(Path(py_file).name)
        self._path = path

    def get_cache_path(self) -> str:
        return self._path

    def get_source_stamp(self) -> str:
        return self._stamp

    def get_disambiguator(self) -> str:
        # the stamp in the file name too: numba unpickles an index before it compares its
        # stamp, and an index written by another version of the kernels may name a type
        # that no longer exists (AttributeError instead of a recompile)
        return f"{self._lineno}-{self._stamp[:12]}"

    @classmethod
    def from_function(cls, py_func: Callable, py_file: str) -> _KernelCacheLocator | None:
        if Path(py_file).resolve().parent != _HERE:
            return None  # not ours: numba's own locators decide
        for base in _cache_bases(py_file):
            self = cls(py_func, py_file, os.path.join(base, "wholebody-kernels", _flavour()))
            try:
                self.ensure_cache_path()
            except OSError:
                continue
            return self
        return None


def _cache_bases(py_file: str) -> list[str]:
    """Candidate cache directories, in order of preference."""
    sub = caching._CacheLocator.get_suitable_cache_subpath(py_file)
    if numba.config.CACHE_DIR:
        return [os.path.join(numba.config.CACHE_DIR, sub)]
    user = caching.AppDirs(appname="numba", appauthor=False).user_cache_dir
    return [os.path.join(os.path.dirname(py_file), "__pycache__"), os.path.join(user, sub)]


if _KernelCacheLocator not in caching.CacheImpl._locator_classes:
    caching.CacheImpl._locator_classes.insert(0, _KernelCacheLocator)


def cache_directory() -> Path | None:
    """The directory the kernels are cached in (None when none is writable)."""
    probe = _KernelCacheLocator.from_function(cache_directory, str(_HERE / "__init__.py"))
    return None if probe is None else Path(probe.get_cache_path())


_DEPTH = [0]  # kernel compilations in progress, nested (numba's compiler lock serialises them)


def _cheap_callees() -> None:
    """Give the libraries of kernels compiled for other kernels only LLVM's cheap pass (module
    docstring, "Compile time"); a no-op where numba's internals are not the known ones."""
    library = getattr(codegen, "CPUCodeLibrary", None)
    full = getattr(library, "_optimize_final_module", None)
    if full is None or getattr(full, "_wholebody", False):
        return

    def optimize(self: codegen.CPUCodeLibrary) -> None:
        if _DEPTH[0] <= 1:  # a kernel Python calls: the whole tree, fully optimised
            full(self)
            return
        pm, pb = self._codegen._module_pass_manager(
            loop_vectorize=False, slp_vectorize=False, opt=0, cost="cheap"
        )
        pm.run(self._final_module, pb)

    optimize._wholebody = True  # type: ignore[attr-defined]
    library._optimize_final_module = optimize


if not DISABLED:
    _cheap_callees()


@contextlib.contextmanager
def as_callees() -> Iterator[None]:
    """Inside the block, the kernels compiled get only the cheap pass, as if another kernel
    called them: to have them in the cache for the kernels that will (``wholebody warmup``);
    their own machine code, for a direct call, is then less optimised."""
    _DEPTH[0] += 1
    try:
        yield
    finally:
        _DEPTH[0] -= 1


def kernel(fn: F) -> F:
    """Compile ``fn`` with numba in nopython mode, cached on disk.

    ``error_model="numpy"``: a float division by zero gives inf or NaN as in numpy (the
    kernels guard the divisions whose result they use), not a Python exception. ``nogil``:
    a kernel releases the GIL, so threads run kernels at once (a batch split over cores).

    A kernel called from another kernel is compiled for its arguments' plain types: numba
    would otherwise compile it once per *literal* constant it is called with (a flag
    ``True``, a region id), and every such copy is optimised again inside each caller
    (compiling the control kernels took three times as long)."""
    dispatcher = numba.njit(cache=True, error_model="numpy", nogil=True)(fn)
    if not DISABLED:
        plain = type(dispatcher).get_call_template

        def get_call_template(args: tuple, kws: dict) -> tuple:
            return plain(
                dispatcher,
                tuple(types.unliteral(a) for a in args),
                {k: types.unliteral(v) for k, v in kws.items()},
            )

        dispatcher.get_call_template = get_call_template
        compile_ = dispatcher.compile

        def compile(sig: tuple) -> object:  # counts the nesting (see _cheap_callees)
            _DEPTH[0] += 1
            try:
                return compile_(sig)
            finally:
                _DEPTH[0] -= 1

        dispatcher.compile = compile
    return dispatcher  # type: ignore[return-value]


def compiling() -> bool:
    """Whether numba is loading or compiling a kernel on this process now (a signal handler
    must not interrupt that: the kernel would be left half loaded)."""
    return _DEPTH[0] > 0


_NOTICE_AFTER = 1.0  # s: a first call that takes longer than this is compiling


@contextlib.contextmanager
def compile_notice(what: str) -> Iterator[None]:
    """Tell the user on stderr when the block takes long enough to be compiling ``what``
    (the first use on this machine), and how long it took; silent when the kernels come
    from the cache."""
    if DISABLED:
        yield
        return
    start = time.perf_counter()
    said = threading.Event()

    def say() -> None:
        said.set()
        where = cache_directory()
        cached = f"; cached in {where}" if where is not None else ""
        print(
            f"wholebody: compiling {what} for this machine (once{cached}) ...",
            file=sys.stderr,
            flush=True,
        )

    timer = threading.Timer(_NOTICE_AFTER, say)
    timer.daemon = True
    timer.start()
    try:
        yield
    finally:
        timer.cancel()
        if said.is_set():
            took = time.perf_counter() - start
            print(f"wholebody: compiled {what} in {took:.1f} s", file=sys.stderr, flush=True)
