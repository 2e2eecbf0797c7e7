"""Where a sweep's cases run: a local process pool, or Ray (a local instance or a cluster).

Both call the same function, :func:`wholebody.sweep.case.run_case`, with the same arguments
(the campaign and one case), and hand every result to ``on_result`` in this process as soon as
the case ends, in whatever order the cases end; the caller writes it (a Ray cluster's workers
need no shared disk: results come back as values).

* :func:`run_local`: ``concurrent.futures.ProcessPoolExecutor`` with ``workers`` processes
  (spawned: no state shared with this one; each loads the cached kernels once);
* :func:`run_ray`: one Ray task per case (``num_cpus=1``; a case's own error is its result,
  never retried; Ray retries a task only when its worker dies), on
  ``ray.init(address=...)``; without an address, a new local Ray instance for this sweep
  that listens on the loopback interface only (:func:`start_local_ray`: refused where Ray
  binds a server elsewhere, unless ``public``). The cluster's nodes need the same wholebody
  (``pip install "wholebody[cluster]"``), and the scenario's files where the campaign names
  them (the bundled ones come with the package).

A Ctrl-C cancels the cases not started and ends those running (a local pool's worker
processes are terminated); their results are not written, so a restart runs them. A
worker that dies fails the cases it held (``--retry-failed`` runs them again) and the sweep
goes on.
"""

from __future__ import annotations

import ipaddress
import multiprocessing
import os
import sys
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from wholebody.errors import ConfigError
from wholebody.sweep.campaign import Campaign, Case
from wholebody.sweep.case import run_case

__all__ = ["exposed_listeners", "run_local", "run_ray", "start_local_ray"]

OnResult = Callable[[dict[str, Any]], None]


def _lost(case: Case, why: str) -> dict[str, Any]:
    """The result of a case whose worker died (not the case's own error: a crash, the
    machine's memory): recorded, so that ``--retry-failed`` runs it again."""
    return {
        "index": case.index,
        "values": case.values,
        "status": "error",
        "metrics": {},
        "error": f"worker lost: {why}",
        "wall_s": 0.0,
    }


def run_local(
    campaign: Campaign,
    cases: Sequence[Case],
    workers: int,
    on_result: OnResult,
    timeout: float | None = None,
) -> None:
    """Run ``cases`` on ``workers`` local processes, at most two cases a worker queued at a
    time, each stopped after ``timeout`` s (:func:`~wholebody.sweep.case.run_case`);
    ``on_result`` for each as it ends. A worker that dies (a crash, out of memory) fails the
    cases it held, the pool is started again and the sweep goes on."""
    todo = list(reversed(cases))
    while todo:
        pool = ProcessPoolExecutor(
            max_workers=min(workers, len(todo)), mp_context=multiprocessing.get_context("spawn")
        )
        try:
            _drain(pool, campaign, todo, 2 * workers, on_result, timeout)
        except BaseException:
            for process in list(getattr(pool, "_processes", {}).values()):
                process.terminate()  # running cases abandoned: a restart runs them
            pool.shutdown(wait=False, cancel_futures=True)
            raise
        pool.shutdown()


def _drain(
    pool: ProcessPoolExecutor,
    campaign: Campaign,
    todo: list[Case],
    window: int,
    on_result: OnResult,
    timeout: float | None,
) -> None:
    """Feed ``todo`` (popped from its end) to ``pool``, ``window`` cases in flight; return
    when it is empty or the pool broke (its cases in flight recorded as lost)."""
    pending: dict = {}
    while todo or pending:
        while todo and len(pending) < window:
            case = todo.pop()
            pending[pool.submit(run_case, campaign, case, timeout)] = case
        done, _ = wait(pending, return_when=FIRST_COMPLETED)
        for future in done:
            case = pending.pop(future)
            try:
                on_result(future.result())
            except BrokenProcessPool as exc:
                on_result(_lost(case, str(exc) or "the worker process died"))
                for other in pending:
                    on_result(_lost(pending[other], "the pool broke"))
                return


LOCAL_ONLY = "RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"
"""Ray's switch (Ray 2.x, read when ``ray`` is imported, inherited by the processes it
starts): at "0" a local instance takes the loopback address as its node's and binds its
servers there; otherwise Ray replaces 127.0.0.1 by the host's address and its servers listen
on the network (measured with Ray 2.60: GCS, raylet and workers on every interface, the
runtime-env agent on the host's address)."""


def run_ray(
    campaign: Campaign,
    cases: Sequence[Case],
    address: str | None,
    on_result: OnResult,
    workers: int | None = None,
    public: bool = False,
    timeout: float | None = None,
) -> None:
    """Run ``cases`` as Ray tasks on the cluster at ``address`` (``"HOST:PORT"``) or, with
    None, on a new local Ray instance (:func:`start_local_ray`; ``workers`` CPUs, ``public``
    as there); at most 1000 in flight, each stopped after ``timeout`` s; ``on_result`` for
    each as it ends. A task lost to a crashed worker or node is recorded as failed."""
    if address:
        ray = _ray()
        ray.init(address=address, include_dashboard=False, log_to_driver=False)
    else:
        ray = start_local_ray(workers, public)
    from ray.exceptions import RayError

    guard = not (address or public)  # (Ray starts workers on demand: checked as it goes)

    pending: dict = {}
    try:
        remote = ray.remote(num_cpus=1)(run_case)
        shared = ray.put(campaign)
        todo = list(reversed(cases))
        while todo or pending:
            while todo and len(pending) < 1000:
                case = todo.pop()
                pending[remote.remote(shared, case, timeout)] = case
            done, _ = ray.wait(list(pending), num_returns=min(len(pending), 16), timeout=1.0)
            if guard:
                _refuse_exposed()
            for ref in done:
                case = pending.pop(ref)
                try:
                    on_result(ray.get(ref))
                except RayError as exc:
                    on_result(_lost(case, f"{type(exc).__name__}: {exc}"[:500]))
    except BaseException:
        for ref in pending:
            ray.cancel(ref, force=True)
        raise
    finally:
        ray.shutdown()


def _ray() -> Any:
    """The ``ray`` module, or a :class:`ConfigError` that says what to install."""
    try:
        import ray
    except ImportError:
        raise ConfigError('--ray needs Ray: pip install "wholebody[cluster]"') from None
    return ray


def start_local_ray(workers: int | None = None, public: bool = False) -> Any:
    """A local Ray instance (``workers`` CPUs, no dashboard) whose servers listen on the
    loopback interface only; returns the ``ray`` module. Ray is put in its local-only mode
    (:data:`LOCAL_ONLY`), then every listening socket of this process and the processes it
    started is checked (:func:`exposed_listeners`; again after each wait of :func:`run_ray`,
    Ray starting workers on demand): one that another host could reach stops the instance
    with a :class:`ConfigError`, unless ``public`` (``--ray-public``), which leaves Ray's own
    choice, the host's address, for a machine meant to take other nodes."""
    ray = _ray()
    if not public:
        exposed_listeners()  # (psutil there before Ray starts)
    constants = sys.modules.get("ray._private.ray_constants")  # (this process read it then)
    saved_env, saved = os.environ.get(LOCAL_ONLY), getattr(constants, "ENABLE_RAY_CLUSTER", None)
    os.environ[LOCAL_ONLY] = "1" if public else "0"  # (for the processes Ray starts)
    if saved is not None:
        constants.ENABLE_RAY_CLUSTER = public
    try:
        ray.init(address="local", num_cpus=workers, include_dashboard=False, log_to_driver=False)
    finally:  # (a later ray.init in this process: Ray's own default again)
        if saved_env is None:
            os.environ.pop(LOCAL_ONLY, None)
        else:
            os.environ[LOCAL_ONLY] = saved_env
        if saved is not None:
            constants.ENABLE_RAY_CLUSTER = saved
    if not public:
        try:
            _refuse_exposed()
        except BaseException:
            ray.shutdown()
            raise
    return ray


def _refuse_exposed() -> None:
    """A :class:`ConfigError` naming the sockets of a local Ray instance that another host
    could reach (:func:`exposed_listeners`), if there is one."""
    exposed = exposed_listeners()
    if exposed:
        raise ConfigError(
            f"the local Ray instance listens on the network ({', '.join(exposed)}), which "
            "this Ray could not be kept from: anyone who reaches this host could submit work "
            "to it. Use the process pool (no --ray), start a head on a private network and "
            "pass its address, or pass --ray-public to allow it"
        )


def exposed_listeners() -> list[str]:
    """The listening sockets of this process and of the processes it started (a local Ray
    instance's servers) that another host could reach, as ``"ADDRESS:PORT (process)"``:
    those not bound to a loopback address (``0.0.0.0`` and ``::`` included)."""
    try:
        import psutil
    except ImportError:
        raise ConfigError(
            '--ray needs psutil to check what Ray listens on: pip install "wholebody[cluster]"'
        ) from None
    me = psutil.Process()
    out = []
    for proc in [me, *me.children(recursive=True)]:
        try:
            name, sockets = proc.name(), proc.net_connections(kind="inet")
        except psutil.Error:  # (a process that ended meanwhile)
            continue
        for sock in sockets:
            if sock.status == psutil.CONN_LISTEN and not _loopback(sock.laddr.ip):
                out.append(f"{sock.laddr.ip}:{sock.laddr.port} ({name})")
    return out


def _loopback(ip: str) -> bool:
    """Whether ``ip`` is a loopback address (an IPv4-mapped one, ``::ffff:127.0.0.1``, too)."""
    address = ipaddress.ip_address(ip.split("%")[0])
    mapped = getattr(address, "ipv4_mapped", None)
    return address.is_loopback or (mapped is not None and mapped.is_loopback)
