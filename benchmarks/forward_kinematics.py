#!/usr/bin/env python3
"""Time the kernels of ``wholebody.kernels.forward`` against Pinocchio called from Python.

Per robot (``--robots``, default the paper's ``mobile_humanoid``), in one thread, the cases
take turns call by call (interleaved, so that drift of this shared machine hits them alike)
at random configurations; printed are the median and p90 per call (us) of

* ``pin fk+J``: ``pin.computeJointJacobians(model, data, q)`` and
  ``pin.updateFramePlacements(model, data)``, what ``Robot.update`` calls;
* ``kernel fk+J``: ``forward_kinematics`` called from Python (numba's dispatch included);
* ``pin integrate``: ``pin.integrate(model, q, v * dt)``;
* ``kernel integrate``: ``integrate`` called from Python;
* ``kernel v=Au + integrate``: ``model_velocity`` and ``integrate``, from ``u``;
* ``Robot.integrate``: the package's Python method (checks, ``A u dt``, ``pin.integrate``);

and, without any Python between calls, the kernels' own cost: ``--inner`` calls in loops
compiled with numba (50 interleaved chunks; the median per call).

The first-compile time of the module (its three kernels, at their first call) is printed
too: run with an empty cache to measure it, ``NUMBA_CACHE_DIR=$(mktemp -d)``.

    NUMBA_CACHE_DIR=$(mktemp -d) python benchmarks/forward_kinematics.py [--calls N]
        [--inner M] [--robots A,B]
"""

from __future__ import annotations

import argparse
import time

import numba
import numpy as np
import pinocchio as pin

import wholebody
from wholebody.kernels.forward import forward_kinematics, integrate, model_velocity


@numba.njit
def _forward_loop(
    model_i: np.ndarray,
    model_f: np.ndarray,
    Q: np.ndarray,
    oMi: np.ndarray,
    oMf: np.ndarray,
    J: np.ndarray,
    inner: int,
) -> None:
    """``inner`` forward kinematics in a compiled loop, over the configurations ``Q``."""
    for k in range(inner):
        forward_kinematics(model_i, model_f, Q[k % Q.shape[0]], oMi, oMf, J)


@numba.njit
def _integrate_loop(
    model_i: np.ndarray, Q: np.ndarray, V: np.ndarray, dt: float, out: np.ndarray, inner: int
) -> None:
    """``inner`` integrations in a compiled loop, over the configurations ``Q``."""
    for k in range(inner):
        integrate(model_i, Q[k % Q.shape[0]], V[k % V.shape[0]], dt, out)


def _first_compile(robot: wholebody.Robot) -> float:
    """Seconds of the first call of the three kernels (compiling, or loading the cache)."""
    kin = robot.kinematics
    model_i, model_f = kin.model_tables()
    m = robot.model
    q, v, u = robot.neutral(), np.zeros(m.nv), np.zeros(robot.nu)
    start = time.perf_counter()
    forward_kinematics(
        model_i,
        model_f,
        q,
        np.empty((m.njoints, 12)),
        np.empty((m.nframes, 12)),
        np.empty((6, m.nv), order="F"),
    )
    model_velocity(kin.act_k, kin.act_j, kin.act_a, u, v)
    integrate(model_i, q, v, 0.01, np.empty(m.nq))
    return time.perf_counter() - start


def bench(name: str, calls: int, inner: int, rng: np.random.Generator) -> None:
    robot = wholebody.load_robot(name)
    m, data, kin = robot.model, robot.data, robot.kinematics
    model_i, model_f = kin.model_tables()
    oMi, oMf = np.empty((m.njoints, 12)), np.empty((m.nframes, 12))
    J, out, v = np.empty((6, m.nv), order="F"), np.empty(m.nq), np.empty(m.nv)
    Q = np.array([robot.random_configuration(rng) for _ in range(64)])
    U = rng.normal(size=(64, robot.nu))
    V = U @ robot.actuation.T
    dt = 0.01
    cases = {
        "pin fk+J": lambda q, u, vv: (
            pin.computeJointJacobians(m, data, q),
            pin.updateFramePlacements(m, data),
        ),
        "kernel fk+J": lambda q, u, vv: forward_kinematics(model_i, model_f, q, oMi, oMf, J),
        "pin integrate": lambda q, u, vv: pin.integrate(m, q, vv * dt),
        "kernel integrate": lambda q, u, vv: integrate(model_i, q, vv, dt, out),
        "kernel v=Au + integrate": lambda q, u, vv: (
            model_velocity(kin.act_k, kin.act_j, kin.act_a, u, v),
            integrate(model_i, q, v, dt, out),
        ),
        "Robot.integrate": lambda q, u, vv: robot.integrate(q, u, dt),
    }
    times = {c: np.empty(calls) for c in cases}
    for f in cases.values():  # warm-up (and compile when the cache is cold)
        f(Q[0], U[0], V[0])
    clock = time.perf_counter_ns
    for k in range(calls):
        q, u, vv = Q[k % 64], U[k % 64], V[k % 64]
        for c, f in cases.items():
            t0 = clock()
            f(q, u, vv)
            times[c][k] = clock() - t0
    _forward_loop(model_i, model_f, Q, oMi, oMf, J, 1)
    _integrate_loop(model_i, Q, V, dt, out, 1)
    chunk, loops = max(inner // 50, 1), np.empty((2, 50))
    for k in range(50):  # interleaved chunks of calls in compiled loops
        t0 = clock()
        _forward_loop(model_i, model_f, Q, oMi, oMf, J, chunk)
        t1 = clock()
        _integrate_loop(model_i, Q, V, dt, out, chunk)
        loops[:, k] = t1 - t0, clock() - t1
    fk_in, int_in = np.median(loops, axis=1) / chunk
    print(
        f"\n{name}: njoints {m.njoints}, nframes {m.nframes}, nq {m.nq}, nv {m.nv}; "
        f"{calls} interleaved calls, one thread"
    )
    print(f"{'case':<26} {'median us':>10} {'p90 us':>8}")
    for c, t in times.items():
        print(f"{c:<26} {np.median(t) / 1e3:>10.2f} {np.percentile(t, 90) / 1e3:>8.2f}")
    print(f"{'kernel fk+J, in-kernel loop':<26} {fk_in / 1e3:>10.2f}")
    print(f"{'integrate, in-kernel loop':<26} {int_in / 1e3:>10.2f}")
    pin_fk, k_fk = np.median(times["pin fk+J"]), np.median(times["kernel fk+J"])
    print(
        f"pin fk+J / kernel fk+J (from Python): {pin_fk / k_fk:.2f}; "
        f"/ in-kernel: {pin_fk / fk_in:.1f}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--calls", type=int, default=20000)
    parser.add_argument("--inner", type=int, default=200000)
    parser.add_argument("--robots", default="mobile_humanoid")
    args = parser.parse_args()
    names = args.robots.split(",")
    first = _first_compile(wholebody.load_robot(names[0]))
    print(
        f"first call of forward_kinematics, model_velocity, integrate: {first:.2f} s "
        "(compile time with an empty NUMBA_CACHE_DIR)"
    )
    rng = np.random.default_rng(0)
    for name in names:
        bench(name, args.calls, args.inner, rng)


if __name__ == "__main__":
    main()
