#!/usr/bin/env python3
"""Cost of one level QP solved by daqp: the kernel (:mod:`wholebody.kernels.daqp`, one
``daqp_quadprog`` per QP) against daqp's Python API, and against a kept workspace.

The QPs are shaped like the hierarchical QP's level QPs: n = 23 variables, 23 simple bounds
and 0, 5 or 10 general rows, the data drifting slowly from one QP to the next as in a
control loop (``--recorded`` adds the level QPs of ``control_step.py``'s tight hierarchy and
collision cases, recorded from the daqp engine while they run). Per QP, in turns (the order
rotating), each of:

* ``kernel``: :func:`wholebody.kernels.daqp.solve` called from Python (numba's dispatch
  included);
* ``daqp.solve``: daqp's one-shot Python call (setup, solve, free);
* ``Model update+solve``: daqp's kept Python workspace, updated with the new data and
  warm-started from the previous working set (what ``DaqpEngine`` does today);
* ``kept (prototype)``: the same kept and warm-started workspace driven from a kernel
  (``setup_daqp`` once, then ``daqp_update_ldp`` + ``daqp_solve``), a measurement-only
  prototype defined here.

Then each whole sequence solved inside one kernel call, with ``daqp_quadprog`` and with the
kept workspace (no dispatch at all): the cost per QP as a kernel that owns the step sees it.
Medians in microseconds.

    python benchmarks/daqp_kernel.py [--steps N] [--repeat R] [--recorded]
"""

from __future__ import annotations

import argparse
import importlib.metadata
import platform
import sys
import time
from pathlib import Path

import daqp
import numba
import numpy as np
from numba import types

from wholebody.kernels import daqp as dk

SETTINGS = {"primal_tol": 1e-9, "iter_limit": 2000}  # the daqp engine's

# The kept-workspace prototype (measurement only). DAQPWorkspace is 328 bytes (41 words); its
# sense pointer is word 8 (offset 64), its settings pointer word 28 (offset 224).
_P = types.uintp
_setup = dk.external_function("setup_daqp", types.int32, _P, _P, _P)
_update = dk.external_function("daqp_update_ldp", types.int32, types.int32, _P, _P)
_solve = dk.external_function("daqp_solve", types.void, _P, _P)
_free_work = dk.external_function("free_daqp_workspace", types.void, _P)
_free_ldp = dk.external_function("free_daqp_ldp", types.void, _P)
_UPDATE = 1 | 2 | 4 | 8 | 16  # DAQP_UPDATE_Rinv | _M | _v | _d | _sense


@numba.njit
def kept(ws, H, f, A, bu, bl, sense, settings, x, lam):
    """One QP on the kept workspace ``ws`` (int64: 41 words of DAQPWorkspace, 10 of the
    problem, 17 of the settings): set up on the first call, updated after, warm-started from
    the previous working set. One structure (n, m, ms) per workspace: free it before another."""
    work, qp, st = ws[:41], ws[41:51], ws[51:68]
    qi = qp.view(np.int32)
    qi[0], qi[1], qi[2] = f.shape[0], bu.shape[0], bu.shape[0] - A.shape[0]
    qp[2], qp[3], qp[4] = H.ctypes.data, f.ctypes.data, A.ctypes.data
    qp[5], qp[6], qp[7] = bu.ctypes.data, bl.ctypes.data, sense.ctypes.data
    if work[28] == 0:
        dk.fill_settings(st, settings)
        work[28] = st.ctypes.data  # daqp uses (and does not free) our settings
        flag = _setup(qp.ctypes.data, work.ctypes.data, 0)
    else:
        qp[7] = work[8]  # sense: the workspace's own (the previous working set)
        flag = _update(_UPDATE, work.ctypes.data, qp.ctypes.data)
    if flag < 0:
        return flag, 0
    res = np.zeros(8, np.int64)
    res[0], res[1] = x.ctypes.data, lam.ctypes.data
    _solve(res.ctypes.data, work.ctypes.data)
    ri = res.view(np.int32)
    return ri[8], ri[9]


@numba.njit
def free(ws):
    """Free what daqp allocated for the kept workspace (not our settings)."""
    if ws[28] != 0:
        ws[28] = 0
        _free_work(ws.ctypes.data)
        _free_ldp(ws.ctypes.data)


@numba.njit
def sequence_quadprog(H, f, A, bu, bl, sense, settings, x, lam):
    for k in range(H.shape[0]):
        dk.solve(H[k], f[k], A[k], bu[k], bl[k], sense, settings, x, lam)


@numba.njit
def sequence_kept(ws, H, f, A, bu, bl, sense, settings, x, lam):
    for k in range(H.shape[0]):
        kept(ws, H[k], f[k], A[k], bu[k], bl[k], sense, settings, x, lam)


def synthetic(rows: int, steps: int, rng: np.random.Generator) -> list[tuple]:
    """n = 23, 23 simple bounds, ``rows`` general rows; the linear term drifts along a slow
    sine, so that consecutive QPs share most of their active bounds."""
    n = 23
    M, A = rng.standard_normal((n + 5, n)), rng.standard_normal((rows, n))
    H = M.T @ M + 1e-3 * np.eye(n)
    f0, df = 3.0 * rng.standard_normal(n), rng.standard_normal(n)
    bu = np.r_[np.full(n, 0.2), np.full(rows, 0.5)]
    return [(H, f0 + 0.3 * np.sin(0.05 * k) * df, A, bu, -bu) for k in range(steps)]


def recorded(steps: int) -> dict[str, list[tuple]]:
    """The level QPs that the daqp engine solves in control_step.py's tight hierarchy and
    collision cases, per engine (level), in order."""
    sys.path.insert(0, str(Path(__file__).parent))
    import control_step as cs

    import wholebody
    from wholebody.solvers import qp as engines
    from wholebody.tasks import FrameTask

    seqs: dict[str, list[tuple]] = {}
    plain = engines.DaqpEngine.solve
    current = {"case": ""}

    def spy(self, H, g, C, lower, upper, lb=None, ub=None):
        box = 0 if lb is None else lb.shape[0]
        bu = np.clip(np.r_[ub if box else [], upper], -1e20, 1e20)
        bl = np.clip(np.r_[lb if box else [], lower], -1e20, 1e20)
        key = (
            f"{current['case']}, level QP {id(self) % 997}: n = {g.shape[0]}, {box} simple bounds, "
            f"{C.shape[0]} rows"
        )
        seqs.setdefault(key, []).append((H.copy(), g.copy(), C.copy(), bu, bl))
        return plain(self, H, g, C, lower, upper, lb, ub)

    engines.DaqpEngine.solve = spy
    robot = wholebody.load_robot("mobile_humanoid")
    q0, refs = cs.hand_references(robot)
    cases = {"tight": cs.hierarchy("daqp", 0.05), "collision": cs.collision("daqp")}
    for case, factory in cases.items():
        current["case"] = case
        hands = [FrameTask(robot, "left_tool", kp=20.0), FrameTask(robot, "right_tool", kp=20.0)]
        stack, solver = factory(robot, hands)
        q = q0.copy()
        for k in range(steps):
            for hand, (pose, twist) in zip(hands, cs.forth_and_back(refs, k * cs.DT), strict=True):
                hand.set_target(pose, twist)
            state = robot.update(q)
            result = solver.solve(stack, state, cs.DT)
            stack.advance(state, cs.DT, result=result)
            q = robot.integrate(q, result.u, cs.DT)
    engines.DaqpEngine.solve = plain
    return {k: v for k, v in seqs.items() if len(v) > 20}


def measure(name: str, seq: list[tuple], repeat: int) -> None:
    n, m = seq[0][1].shape[0], seq[0][3].shape[0]
    s = dk.settings(**SETTINGS)
    sense = np.zeros(m, np.int32)
    x, lam, xk, lamk = np.empty(n), np.empty(m), np.empty(n), np.empty(m)
    model = daqp.Model()
    model.settings = SETTINGS
    model.setup(*seq[0], np.zeros(m, np.int32))
    ws = np.zeros(68, np.int64)
    times: dict[str, list[float]] = {
        "kernel": [],
        "daqp.solve": [],
        "Model update+solve": [],
        "kept (prototype)": [],
    }
    names = list(times)
    iters: dict[str, list[int]] = {"cold": [], "warm": []}
    dx = 0.0
    for r in range(repeat):
        for j, (H, f, A, bu, bl) in enumerate(seq):
            for case in names[j % 4 :] + names[: j % 4]:
                start = time.perf_counter_ns()
                if case == "kernel":
                    flag, it = dk.solve(H, f, A, bu, bl, sense, s, x, lam)
                elif case == "daqp.solve":
                    xr, _, flag_r, _ = daqp.solve(H, f, A, bu, bl, sense, **SETTINGS)
                elif case == "Model update+solve":
                    model.update(H=H, f=f, bupper=bu, blower=bl, **({"A": A} if A.shape[0] else {}))
                    xm, _, flag_m, _ = model.solve()
                else:
                    flag_k, it_k = kept(ws, H, f, A, bu, bl, sense, s, xk, lamk)
                times[case].append((time.perf_counter_ns() - start) / 1e3)
            if r == 0:
                assert flag == flag_r == flag_m == flag_k == dk.OPTIMAL, (flag, flag_r, flag_m)
                iters["cold"].append(it)
                iters["warm"].append(it_k)
                dx = max(dx, np.abs(x - xr).max(), np.abs(xk - x).max(), np.abs(xm - xk).max())
    stacked = [np.ascontiguousarray(np.stack([q[i] for q in seq])) for i in range(5)]
    whole: dict[str, list[float]] = {"quadprog": [], "kept": []}
    for _ in range(max(repeat, 5)):
        start = time.perf_counter_ns()
        sequence_quadprog(*stacked, sense, s, x, lam)
        whole["quadprog"].append((time.perf_counter_ns() - start) / 1e3 / len(seq))
        free(ws)  # each sequence from a fresh workspace
        start = time.perf_counter_ns()
        sequence_kept(ws, *stacked, sense, s, x, lam)
        whole["kept"].append((time.perf_counter_ns() - start) / 1e3 / len(seq))
    free(ws)
    print(
        f"\n{name}: {len(seq)} QPs x {repeat}; iterations median (max): cold "
        f"{np.median(iters['cold']):.0f} ({max(iters['cold'])}), warm "
        f"{np.median(iters['warm']):.0f} ({max(iters['warm'])}); largest |x difference| "
        f"between the four {dx:.1e}"
    )
    for case, t in times.items():
        print(f"  {case:34s} {np.median(t):7.2f} us   (p90 {np.percentile(t, 90):6.2f})")
    for case, t in whole.items():
        print(f"  {'in one kernel call, ' + case:34s} {np.median(t):7.2f} us")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=300, help="QPs per sequence")
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument(
        "--recorded",
        action="store_true",
        help="also the level QPs recorded from control_step.py (compiles)",
    )
    args = parser.parse_args()
    print(
        f"daqp {importlib.metadata.version('daqp')}, level QPs, "
        f"{platform.processor() or platform.machine()}, Python {platform.python_version()}"
    )
    rng = np.random.default_rng(1)
    seqs = {
        f"synthetic: n = 23, 23 simple bounds, {rows} rows": synthetic(rows, args.steps, rng)
        for rows in (0, 5, 10)
    }
    if args.recorded:
        seqs.update(recorded(args.steps))
    for name, seq in seqs.items():
        measure(name, seq, args.repeat)


if __name__ == "__main__":
    main()
