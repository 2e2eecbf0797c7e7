"""The memory layout of a compiled stack: named regions of two flat arenas.

A compiled stack (:class:`wholebody.solvers.plan.Plan`) keeps all its numbers in one float64
arena ``f`` and one int64 arena ``i``, cut into the regions named below. The header ``h``
(one row per region: offset, size, then up to three dimensions) says where each region lies
and its shape, so a kernel takes ``(f, i, h)`` and three Pinocchio arrays instead of forty
arguments (numba's call overhead grows by about 70 ns per array argument), and reads a region
as a view: ``fmat(f, h, F_A)`` is the (K, nu) matrix of task rows.

The Python side writes a region through the same views (:meth:`Plan.view`); nothing is copied
between the two.
"""

from __future__ import annotations

import numpy as np

from wholebody.kernels import kernel

# ------------------------------------------------------------------ float regions
F_SCALARS = 0  # (4,): dt (s), then scratch
F_ACT_A = 1  # (E,): values of the actuation matrix's non-zero entries
F_KIN_J = 2  # (F, 6, nu): frame Jacobians, actuated coordinates
F_KIN_P = 3  # (F, 3): frame positions (m)
F_KIN_R = 4  # (F, 3, 3): frame rotations
F_JP = 5  # (nu,): joint positions (rad, m)
F_POSE = 6  # (nP, POSE_WIDTH): pose tasks' gains, targets, integrals, errors
F_POSTURE = 7  # (3, nE): posture entries' target (rad, m), gain (1/s), error (out)
F_HALF = 8  # (nH, 5): half-spaces' normal (3), offset (m), gain
F_ARM = 9  # (nA, AE_WIDTH): arm energies' parameters (kernels.objectives)
F_ARM_PARTS = 10  # (nA, ARM_PARTS): arm energies' parts (out)
F_NETS = 11  # (n,): packed stiffness networks
F_H1 = 12  # (nB, 3, nu): joint-limit avoidance's lo, hi, c
F_OBJ = 13  # (nO, 2): objectives' weight, value (out)
F_OBJ_GRAD = 14  # (nO, nu): objectives' gradients
F_OBJ_CURV = 15  # (nO, nu): objectives' Hessian diagonals
F_POS_BOX = 16  # (nJ, 3, nu): position limits' lower + margin, upper - margin, gain
F_VEL_BOX = 17  # (nV, nu): velocity limits' upper bound (the lower is its negative)
F_PY_BOX = 18  # (nC, 2, nu): boxes of constraints written in Python
F_METRIC = 19  # (2, nu): D = W^-1/2 and D^2
F_ROW = 20  # (2, K): per row, sqrt(w) and its inverse (0 where w = 0; objective rows: 0)
F_LEVEL = 21  # (L, 4): gain, objective weight, identity scale (out), reference scale
F_A = 22  # (K, nu): equality rows, scaled (out)
F_B = 23  # (K,): right-hand sides, scaled (out)
F_C = 24  # (P, nu): inequality rows, scaled (out)
F_CB = 25  # (2, P): inequality rows' lower and upper bounds
F_BOX = 26  # (2, nu): the box in scaled coordinates (out)
F_U = 27  # (2, nu): the solution, in scaled and in actuated coordinates (out)
F_LEVEL_OUT = 28  # (L, 2): per level, residual and scale factor (out)
F_TASK_RES = 29  # (T, 3): per equality task, weighted, unweighted residual and |b| (out)
N_FLOAT = 30

# ------------------------------------------------------------------ int regions
I_FRAME = N_FLOAT + 0  # (F,): frame indices into data.oMf
I_SUPPORT = N_FLOAT + 1  # (F, nv): 1 where the velocity coordinate moves the frame
I_ACT = N_FLOAT + 2  # (2, E): the actuation matrix's non-zero entries (column k, row j)
I_POS = N_FLOAT + 3  # (2, nu): joint positions: index into q, (cos, sin) pair
I_POSE = N_FLOAT + 4  # (nP, POSE_INTS): frames, rows, row selection
I_POSTURE = N_FLOAT + 5  # (nQ, 3): posture tasks' first row, first entry, entries
I_POSTURE_ENTRY = N_FLOAT + 6  # (3, nE): index into u, tracked, wrapped
I_HALF = N_FLOAT + 7  # (nH, 2): half-spaces' frame and inequality row
I_ARM = N_FLOAT + 8  # (nA, 6): arm energies' frames
I_H2 = N_FLOAT + 9  # (nM, 1 + Fmax): manipulabilities' frame count and frames
I_H2_MASK = N_FLOAT + 10  # (nu, nu): 1 where column l supports column k
I_OBJ = N_FLOAT + 11  # (nO, 4): objectives' kind, index in its table, level, curvature
I_LEVEL = N_FLOAT + 12  # (L, LEVEL_INTS): rows of each level
I_TASK = N_FLOAT + 13  # (T, 3): equality tasks' level, first and last row
I_BOX = N_FLOAT + 14  # (3,): number of position, velocity and Python boxes
I_OUT = N_FLOAT + 15  # (OUT_INTS,): solver outcome codes (out)
I_ACTIVE = N_FLOAT + 16  # (nu,): 1 where u is on a bound (out)
I_INFEASIBLE = N_FLOAT + 17  # (T,): 1 where a task is not met (out)
I_INEQ = N_FLOAT + 18  # (Pt, 3): inequality tasks' level, first and last row
N_REGIONS = N_FLOAT + 19

HEADER_WIDTH = 5  # offset, size, d0, d1, d2

# pose tasks: I_POSE columns
POSE_FA, POSE_FB, POSE_ROW, POSE_NROWS, POSE_SEL = 0, 1, 2, 3, 4  # rows selected: 4..9
POSE_INTS = 10
# F_POSE columns
POSE_KP, POSE_KI, POSE_TARGET, POSE_TWIST, POSE_INTEGRAL, POSE_ERROR = 0, 6, 12, 28, 34, 40
POSE_WIDTH = 46

# objectives: I_OBJ columns and kinds
OBJ_KIND, OBJ_INDEX, OBJ_LEVEL, OBJ_HAS_CURV = 0, 1, 2, 3
KIND_PYTHON, KIND_ARM, KIND_H1, KIND_H2 = 0, 1, 2, 3

# levels: I_LEVEL columns
LEVEL_ROW0, LEVEL_TASKS_END, LEVEL_ROW_END, LEVEL_INEQ0, LEVEL_INEQ_END = 0, 1, 2, 3, 4
LEVEL_HAS_TASKS = 5  # 1 when the level holds equality tasks (a level of objectives only: 0)
LEVEL_INTS = 6
# F_LEVEL columns
LEVEL_GAIN, LEVEL_OBJECTIVE_WEIGHT, LEVEL_IDENTITY, LEVEL_REFERENCE = 0, 1, 2, 3

# I_OUT entries
OUT_STATUS, OUT_FAILED, OUT_MESSAGE = 0, 1, 2
OUT_INTS = 4


@kernel
def fvec(f: np.ndarray, h: np.ndarray, r: int) -> np.ndarray:
    """Float region ``r`` as a 1-D view."""
    o = h[r, 0]
    return f[o : o + h[r, 1]]


@kernel
def fmat(f: np.ndarray, h: np.ndarray, r: int) -> np.ndarray:
    """Float region ``r`` as a 2-D view."""
    o = h[r, 0]
    return f[o : o + h[r, 1]].reshape((h[r, 2], h[r, 3]))


@kernel
def ften(f: np.ndarray, h: np.ndarray, r: int) -> np.ndarray:
    """Float region ``r`` as a 3-D view."""
    o = h[r, 0]
    return f[o : o + h[r, 1]].reshape((h[r, 2], h[r, 3], h[r, 4]))


@kernel
def ivec(i: np.ndarray, h: np.ndarray, r: int) -> np.ndarray:
    """Int region ``r`` as a 1-D view."""
    o = h[r, 0]
    return i[o : o + h[r, 1]]


@kernel
def imat(i: np.ndarray, h: np.ndarray, r: int) -> np.ndarray:
    """Int region ``r`` as a 2-D view."""
    o = h[r, 0]
    return i[o : o + h[r, 1]].reshape((h[r, 2], h[r, 3]))


def build(shapes: dict[int, tuple[int, ...]], n_float: int = N_FLOAT,
          n_regions: int = N_REGIONS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """The arenas ``(f, i)`` and header ``h`` for regions of the given shapes (every region
    id below ``n_regions`` must be given; float ids below ``n_float``); zeroed."""
    h = np.zeros((n_regions, HEADER_WIDTH), dtype=np.int64)
    sizes = [0, 0]
    for r in range(n_regions):
        shape = tuple(int(d) for d in shapes[r])
        if not 1 <= len(shape) <= 3 or min(shape) < 0:
            raise ValueError(f"region {r}: bad shape {shape}")
        size = int(np.prod(shape))
        kind = 0 if r < n_float else 1
        h[r, 0], h[r, 1] = sizes[kind], size
        h[r, 2 : 2 + len(shape)] = shape
        sizes[kind] += size
    return np.zeros(max(sizes[0], 1)), np.zeros(max(sizes[1], 1), dtype=np.int64), h


def view(arena: np.ndarray, h: np.ndarray, r: int, shape: tuple[int, ...]) -> np.ndarray:
    """Region ``r`` of ``arena`` as a numpy view of ``shape`` (the Python side's access)."""
    o, n = int(h[r, 0]), int(h[r, 1])
    return arena[o : o + n].reshape(shape)
