"""The memory layout of a compiled stack: named regions of two flat arenas.

A compiled stack (:class:`wholebody.solvers.plan.Plan`) keeps all its numbers in one float64
arena ``f`` and one int64 arena ``i``, cut into the regions named below. The header ``h``
(one row per region: offset, size, then up to three dimensions) says where each region lies
and its shape, so a kernel takes ``(f, i, h)`` and three Pinocchio arrays instead of forty
arguments (numba's call overhead grows by about 70 ns per array argument), and reads a region
as a view: ``fmat(f, h, F_A)`` is the (K, nu) matrix of task rows.

Every task, inequality task, objective and limit of the stack is one row of the **entry
table** ``I_ENTRY``: its category, its kind (which kernel computes it, or ``KIND_PYTHON``:
written by Python before the kernel runs), its level, its first row and row count (in ``F_A``
for a task, in ``F_C`` for an inequality task), its slot (an objective's row of ``F_OBJ*``, a
limit's box in ``F_BOXES``, a task's index in ``I_TASK``), the reference it follows, where its
own numbers lie in the parameter regions ``F_PAR`` and ``I_PAR`` (what the entry packed there
itself: :meth:`wholebody.tasks.Task.pack`), and a flag (an objective's gradient comes with a
curvature). The Python side writes a region through the same views (:meth:`Plan.view`);
nothing is copied between the two.
"""

from __future__ import annotations

import numpy as np

from wholebody.kernels import kernel

# ------------------------------------------------------------------ float regions
F_SCALARS = 0  # (4,): dt (s), whether an anchor is set, then scratch
F_ACT_A = 1  # (E,): values of the actuation matrix's non-zero entries
F_KIN_J = 2  # (F, 6, nu): frame Jacobians, actuated coordinates
F_KIN_P = 3  # (F, 3): frame positions (m)
F_KIN_R = 4  # (F, 3, 3): frame rotations
F_JP = 5  # (nu,): joint positions (rad, m)
F_PAR = 6  # (n,): every compiled entry's parameters and state (its own layout)
F_OBJ = 7  # (nO, 2): objectives' weight, value (out)
F_OBJ_GRAD = 8  # (nO, nu): objectives' gradients
F_OBJ_CURV = 9  # (nO, nu): objectives' Hessian diagonals
F_BOXES = 10  # (nC, 2, nu): every limit's box, lower and upper (rad/s, m/s)
F_METRIC = 11  # (2, nu): D = W^-1/2 and D^2
F_ROW = 12  # (2, K): per row, sqrt(w) and its inverse (0 where w = 0; objective rows: 0)
F_LEVEL = 13  # (L, 4): gain, objective weight, identity scale (out), reference scale
F_A = 14  # (K, nu): equality rows, scaled (out)
F_B = 15  # (K,): right-hand sides, scaled (out)
F_C = 16  # (P, nu): inequality rows, scaled (out)
F_CB = 17  # (2, P): inequality rows' lower and upper bounds
F_BOX = 18  # (4, nu): the box, then without acceleration limits, scaled (out)
F_ANCHOR = 19  # (nu,): the last velocity of the acceleration limits (scaled; 0 without)
F_U = 20  # (2, nu): the solution, in scaled and in actuated coordinates (out)
F_LEVEL_OUT = 21  # (L, 2): per level, residual and scale factor (out)
F_TASK_RES = 22  # (T, 3): per equality task, weighted, unweighted residual and |b| (out)
N_FLOAT = 23

# ------------------------------------------------------------------ int regions
I_FRAME = N_FLOAT + 0  # (F,): frame indices into data.oMf
I_SUPPORT = N_FLOAT + 1  # (F, nv): 1 where the velocity coordinate moves the frame
I_ACT = N_FLOAT + 2  # (2, E): the actuation matrix's non-zero entries (column k, row j)
I_POS = N_FLOAT + 3  # (2, nu): joint positions: index into q, (cos, sin) pair
I_ENTRY = N_FLOAT + 4  # (nE, ENTRY_INTS): the entry table (see the module docstring)
I_PAR = N_FLOAT + 5  # (n,): every compiled entry's integer parameters
I_LEVEL = N_FLOAT + 6  # (L, LEVEL_INTS): rows of each level
I_TASK = N_FLOAT + 7  # (T, 3): equality tasks' level, first and last row
I_OUT = N_FLOAT + 8  # (OUT_INTS,): solver outcome codes (out)
I_ACTIVE = N_FLOAT + 9  # (nu,): 1 where u is on a bound (out)
I_INFEASIBLE = N_FLOAT + 10  # (T,): 1 where a task is not met (out)
I_SATURATED = N_FLOAT + 11  # (T,): 1 where the bounds limited a task (anti-windup; out)
I_INEQ = N_FLOAT + 12  # (Pt, 3): inequality tasks' level, first and last row
I_HELD = N_FLOAT + 13  # (P,): projection: inequality rows held, HELD_MET or HELD_UNMET (out)
I_UNMET0 = N_FLOAT + 14  # (T,): projection: tasks unmet before any row was held (out)
N_REGIONS = N_FLOAT + 15

HEADER_WIDTH = 5  # offset, size, d0, d1, d2

# the entry table: I_ENTRY columns
E_CAT, E_KIND, E_LEVEL, E_ROW, E_ROWS, E_SLOT, E_REF, E_F0, E_FN, E_I0, E_IN, E_FLAG = range(12)
ENTRY_INTS = 12  # E_FLAG: an objective's gradient comes with a curvature
# categories: what an entry is
CAT_TASK, CAT_INEQUALITY, CAT_OBJECTIVE, CAT_LIMIT = 0, 1, 2, 3
# kinds: which kernel computes it; KIND_PYTHON entries are written by Python before the
# kernel runs
KIND_PYTHON = 0
KIND_POSE, KIND_POSTURE = 1, 2  # tasks (and KIND_COM below)
KIND_HALF_SPACE, KIND_COLLISION = 3, 4  # inequality tasks
KIND_ARM, KIND_H1, KIND_H2 = 5, 6, 7  # objectives
KIND_POSITION, KIND_VELOCITY, KIND_ACCELERATION = 8, 9, 10  # limits
KIND_COM = 11  # a task: the whole-body centre of mass

# levels: I_LEVEL columns
LEVEL_ROW0, LEVEL_TASKS_END, LEVEL_ROW_END, LEVEL_INEQ0, LEVEL_INEQ_END = 0, 1, 2, 3, 4
LEVEL_HAS_TASKS = 5  # 1 when the level holds equality tasks (a level of objectives only: 0)
LEVEL_INTS = 6
# F_LEVEL columns
LEVEL_GAIN, LEVEL_OBJECTIVE_WEIGHT, LEVEL_IDENTITY, LEVEL_REFERENCE = 0, 1, 2, 3

# I_HELD values: not held, held at its bound, held but the box kept it from its bound
HELD_NOT, HELD_MET, HELD_UNMET = 0, 1, 2

# I_OUT entries
OUT_STATUS, OUT_FAILED, OUT_MESSAGE, OUT_EXTRA = 0, 1, 2, 3
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


def build(
    shapes: dict[int, tuple[int, ...]], n_float: int = N_FLOAT, n_regions: int = N_REGIONS
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
