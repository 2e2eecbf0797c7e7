"""The paper's figures from a run log (PNG, headless: figures are drawn on matplotlib's Agg
canvas without pyplot, so importing this module changes no matplotlib state).

* :func:`hand_paths`: executed hand paths in 3-D with their references, coloured by phase,
  each phase's goal marked and named, the obstacles, the props and a carried object at a
  few instants (Figs. 9, 10, 15); when the hands travel metres (a drive), panels near the
  hands at the first goal and at the end keep the grasp and the placing readable;
* :func:`joint_velocities`: actuated velocities per group, left arm, right arm, waist and
  wheels first (Figs. 12, 17), then the robot's other groups; phases shaded and named;
* :func:`arm_energy`: per arm, gravity and spring energy over time, the arm angle over time
  and the spring energy against the arm angle, coloured by time (Fig. 13).

Each writes a PNG; ``*_figure`` returns the :class:`~matplotlib.figure.Figure` instead (to
show in a notebook or adjust). They are made to be quick, since every run writes them:
fixed margins instead of a layout engine (``tight_layout`` draws the figure once more to
measure it), panel titles at a fixed height (an automatic one measures the ticks below it),
about five ticks an axis, long traces thinned to about two points a pixel column
(:func:`thin`, keeping each bucket's extremes, so a one-step spike still shows), PNGs
compressed lightly.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Patch, Rectangle
from matplotlib.ticker import MaxNLocator
from matplotlib.transforms import offset_copy

from wholebody.control.log import RunLog
from wholebody.control.metrics import ARM_ANGLE_MIN_RHO
from wholebody.files import save_figure
from wholebody.scenarios.spec import ObjectSpec

__all__ = [
    "PHASE_COLORS",
    "arm_energy",
    "arm_energy_figure",
    "break_wraps",
    "hand_paths",
    "hand_paths_figure",
    "joint_velocities",
    "joint_velocities_figure",
    "phase_goals",
    "thin",
]

PHASE_COLORS = (
    "#1f77b4",
    "#ff7f0e",
    "#9467bd",
    "#8c564b",
    "#e377c2",
    "#17becf",
    "#bcbd22",
    "#7f7f7f",
)
"""One colour per phase, in order, the same in every figure (no red: obstacles; no green:
carried objects)."""
OBSTACLE, PROP, CARRIED = "#d62728", "0.45", "#2ca02c"
DRIVE_EXTENT = 2.5
"""m: hand paths spanning more than this (a drive) get panels near the hands."""
GOAL_MOVE = 0.01
"""m: a phase whose reference moves more than this has a goal (its end) to mark."""
MAX_POINTS = 1200
"""Points drawn per trace at most (about two per pixel column of the widest panel)."""
_PNG = {"dpi": 100, "pil_kwargs": {"compress_level": 1}}
_MPL = tuple(int(v) for v in matplotlib.__version__.split(".")[:2])
_CLIP3D = {"axlim_clip": True} if _MPL >= (3, 10) else {}  # 3-D lines clipped to the axes


def _figure(**kw) -> Figure:
    """A figure on matplotlib's Agg canvas (no pyplot, no interactive backend)."""
    fig = Figure(**kw)
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, out: Path) -> Path:
    """Write the PNG atomically (lightly compressed: the default level costs several times
    as long for files a third smaller)."""
    return save_figure(fig, out, **_PNG)


def _margins(fig: Figure, left: float, right: float, bottom: float, top: float, **kw) -> None:
    """Fixed margins in inches (no layout engine: one draw instead of two or three)."""
    w, h = fig.get_size_inches()
    fig.subplots_adjust(
        left=left / w, right=1 - right / w, bottom=bottom / h, top=1 - top / h, **kw
    )


def thin(t: np.ndarray, y: np.ndarray, n_max: int = MAX_POINTS) -> tuple[np.ndarray, np.ndarray]:
    """At most about ``n_max`` samples per column of the trace ``y(t)`` (``y`` (N,) or
    (N, k)): the samples cut into ``n_max / 2`` buckets, each kept as its minimum and its
    maximum (of every column) in time order, so a spike of one sample survives; the first
    sample of every gap (NaN) and the first after it are kept, so gaps stay gaps."""
    n = len(t)
    if n <= n_max:
        return t, y
    flat = np.asarray(y, dtype=float).reshape(n, -1)
    edges = np.linspace(0, n, max(1, n_max // 2) + 1).astype(int)
    starts = edges[:-1][np.diff(edges) > 0]
    lows = np.minimum.reduceat(np.where(np.isnan(flat), np.inf, flat), starts, axis=0)
    highs = np.maximum.reduceat(np.where(np.isnan(flat), -np.inf, flat), starts, axis=0)
    bucket = np.repeat(np.arange(len(starts)), np.diff(np.append(starts, n)))
    extreme = (flat == lows[bucket]) | (flat == highs[bucket])
    gap = np.isnan(flat).any(axis=1)
    edge = np.flatnonzero(np.diff(gap.astype(int))) + 1  # first row of a gap and after it
    keep = extreme.any(axis=1)
    keep[starts] = True
    keep[edge] = True
    keep[-1] = True
    return t[keep], np.asarray(y)[keep]


def break_wraps(
    t: np.ndarray, angle: np.ndarray, period: float = 2 * np.pi
) -> tuple[np.ndarray, np.ndarray]:
    """``(t, angle)`` (s, rad) with a NaN sample inserted between two samples that differ
    by more than half a ``period``: an angle wrapping from pi to -pi is drawn broken there,
    not as a line across the whole axis."""
    angle = np.asarray(angle, dtype=float)
    jumps = np.flatnonzero(np.abs(np.diff(angle)) > period / 2) + 1
    if not len(jumps):
        return t, angle
    t_mid = (t[jumps - 1] + t[jumps]) / 2
    return np.insert(t, jumps, t_mid), np.insert(angle, jumps, np.nan)


def _phases(log: RunLog) -> list[tuple[str, float, float, str]]:
    """``(name, start s, end s, colour)`` of every phase in order."""
    phases = log.meta.get("phases", {})
    return [
        (name, float(t0), float(t1), PHASE_COLORS[i % len(PHASE_COLORS)])
        for i, (name, (t0, t1)) in enumerate(phases.items())
    ]


def _phase_rows(log: RunLog) -> list[tuple[str, int, int, str]]:
    """``(name, first step, last step, colour)`` of every phase with steps; a log without
    phases is one phase named ``run``."""
    out = []
    for name, _, _, color in _phases(log):
        rows = np.flatnonzero(log.phase_mask(name))
        if len(rows):
            out.append((name, int(rows[0]), int(rows[-1]), color))
    return out or [("run", 0, len(log) - 1, PHASE_COLORS[0])]


def _joined(first: int, last: int, n: int) -> slice:
    """A phase's steps and the next phase's first one: paths drawn phase by phase join."""
    return slice(first, min(last + 2, n))


def phase_goals(log: RunLog, tol: float = 0.03) -> list[tuple[np.ndarray, str, str]]:
    """Each phase's goal as ``(position (3,) m, label, colour)``: where a hand's reference
    ends in a phase in which it moved more than :data:`GOAL_MOVE`. Goals of several phases
    closer than ``tol`` m (returns to one place) share one marker, their names joined."""
    goals: list[list] = []
    for name, first, last, color in _phase_rows(log):
        for ref in log.reference_positions.values():
            seg = ref[first : last + 1]
            seg = seg[np.isfinite(seg).all(axis=1)]
            if len(seg) < 2 or np.linalg.norm(seg[-1] - seg[0]) <= GOAL_MOVE:
                continue
            near = next((g for g in goals if np.linalg.norm(g[0] - seg[-1]) < tol), None)
            if near is None:
                goals.append([seg[-1], name, color])
            elif name not in near[1].split(", "):
                near[1] += f", {name}"
    return [(p, label, color) for p, label, color in goals]


# ---------------------------------------------------------------------- objects
def _box_edges(center: np.ndarray, size: np.ndarray, R: np.ndarray) -> list[np.ndarray]:
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    pts = center + (corners * size / 2) @ R.T
    edges = []
    for i in range(8):
        for j in range(i + 1, 8):
            if np.sum(corners[i] != corners[j]) == 1:
                edges.append(pts[[i, j]])
    return edges


def _draw_object(
    ax, obj: ObjectSpec, pose: np.ndarray | None = None, color=PROP, alpha=0.6
) -> None:
    """An object's wire frame in a 3-D axes (one line collection per object)."""
    c = np.asarray(obj.position) if pose is None else pose[:3, 3]
    R = np.eye(3) if pose is None else pose[:3, :3]
    if obj.kind == "box":  # edges cut into short pieces: a zoomed axes clips by the point
        segments = [np.linspace(a, b, 17) for a, b in _box_edges(c, np.asarray(obj.size), R)]
    elif obj.kind == "cylinder":
        th = np.linspace(0, 2 * np.pi, 25)
        rim = np.column_stack([obj.radius * np.cos(th), obj.radius * np.sin(th), np.zeros_like(th)])
        h = np.array([0.0, 0.0, obj.height / 2])
        segments = [c + rim - h, c + rim + h] + [np.array([c + p - h, c + p + h]) for p in rim[::4]]
    else:
        th = np.linspace(0, 2 * np.pi, 25)
        circle = obj.radius * np.column_stack([np.cos(th), np.sin(th), np.zeros_like(th)])
        segments = [c + circle[:, order] for order in ([0, 1, 2], [0, 2, 1], [2, 0, 1])]
    _lines3d(ax, segments, color=color, alpha=alpha, lw=1)


def _lines3d(ax, segments: list[np.ndarray], **kw) -> None:
    """Many 3-D polylines as one artist (NaN-separated): one draw call, not one per line."""
    pts = np.vstack([np.vstack([s, np.full((1, 3), np.nan)]) for s in segments])
    ax.plot(*pts.T, **kw, **_CLIP3D)


# ---------------------------------------------------------------------- hand paths
def _inside(p: np.ndarray, window: tuple[np.ndarray, np.ndarray] | None) -> np.ndarray:
    """Whether each point of ``p`` (..., 3) lies in the box ``window`` = (lo, hi) (all do
    without a window)."""
    if window is None:
        return np.ones(p.shape[:-1], dtype=bool)
    return np.all((p >= window[0]) & (p <= window[1]), axis=-1)


def _draw_paths3d(ax, log: RunLog, window: tuple[np.ndarray, np.ndarray] | None = None) -> None:
    """Every hand's executed (solid) and reference (dashed) path, one colour per phase, its
    start (circle, named) and the phases' goals (crosses, named). ``window``: (lo, hi)
    corners (m); the points outside are blanked (a 3-D axes does not clip)."""
    n = len(log)
    for hand, pos in log.frame_positions.items():
        ref = log.reference_positions[hand]
        out = ~_inside(pos, window)[:, None]
        shown, shown_ref = np.where(out, np.nan, pos), np.where(out, np.nan, ref)
        for _, first, last, color in _phase_rows(log):
            steps = _joined(first, last, n)
            _, p = thin(log.t[steps], shown[steps], MAX_POINTS // 2)
            _, r = thin(log.t[steps], shown_ref[steps], MAX_POINTS // 2)
            ax.plot(*p.T, color=color, lw=1.8, **_CLIP3D)
            ax.plot(*r.T, color=color, lw=0.9, ls="--", **_CLIP3D)
        start = pos[np.isfinite(pos).all(axis=1)][:1]
        if len(start) and _inside(start[0], window):
            ax.scatter(*start[0], color="k", marker="o", s=22, zorder=5)
            ax.text(*start[0], f"{hand}  ", fontsize=7, ha="right")
    for p, label, color in phase_goals(log):
        if _inside(p, window):
            ax.scatter(*p, color=color, marker="x", s=45, linewidths=2, zorder=6)
            ax.text(*p, f" {label}", fontsize=7, color=color)


def _equal_limits(ax, lo: np.ndarray, hi: np.ndarray, pad: float = 0.1) -> None:
    """Equal scales on the three axes around the box ``lo``-``hi`` (m)."""
    mid, half = (hi + lo) / 2, float(np.max(hi - lo)) / 2 + pad
    for setter, m in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), mid, strict=True):
        setter(m - half, m + half)
    ax.set_box_aspect((1, 1, 1))


def _axes3d(ax, title: str) -> None:
    ax.set_xlabel("x (m)", labelpad=-2)
    ax.set_ylabel("y (m)", labelpad=-2)
    ax.set_zlabel("z (m)", labelpad=-2)
    ax.tick_params(labelsize=7, pad=0)
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.set_major_locator(MaxNLocator(5))
    _title(ax, title)


def _draw_objects3d(
    ax,
    objects: Mapping[str, ObjectSpec],
    carried: Mapping[str, np.ndarray],
    window: tuple[np.ndarray, np.ndarray] | None = None,
) -> None:
    """Obstacles (red), props (grey) and each carried object at five instants (green); in a
    ``window``, only what lies within it (by its centre, grown by 0.3 m)."""

    def inside(obj: ObjectSpec, centre: np.ndarray) -> bool:
        if window is None:
            return True
        half = _half_extent(obj)
        return bool(np.all((centre + half >= window[0]) & (centre - half <= window[1])))

    for obj in objects.values():
        if inside(obj, np.asarray(obj.position)):
            _draw_object(ax, obj, color=OBSTACLE if obj.obstacle else PROP)
    for name, poses in carried.items():
        if name in objects and not np.allclose(poses[0], poses[-1]):
            for k in np.linspace(0, len(poses) - 1, 5).astype(int):
                if inside(objects[name], poses[k][:3, 3]):
                    _draw_object(ax, objects[name], poses[k], color=CARRIED, alpha=0.8)


def _half_extent(obj: ObjectSpec) -> np.ndarray:
    """Half the size of an object's axis-aligned bounding box (m), whatever its turn (a
    box's half diagonal on every axis)."""
    if obj.kind == "box":
        return np.full(3, float(np.linalg.norm(obj.size)) / 2)
    if obj.kind == "cylinder":
        return np.array([obj.radius, obj.radius, obj.height / 2])
    return np.full(3, float(obj.radius))


def _bounds(log: RunLog, objects: Mapping[str, ObjectSpec]) -> tuple[np.ndarray, np.ndarray]:
    """The box (lo, hi) (m) holding every hand path and every object where it starts."""
    pts = [p[np.isfinite(p).all(axis=1)] for p in log.frame_positions.values()]
    for obj in objects.values():
        c, half = np.asarray(obj.position, dtype=float), _half_extent(obj)
        pts.append(np.array([c - half, c + half]))
    pts = np.vstack(pts)
    return pts.min(axis=0), pts.max(axis=0)


def _windows(log: RunLog) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """Zoom windows ``(title, lo, hi)`` for a run whose hands travel more than
    :data:`DRIVE_EXTENT`: around the hands at the end of the first phase with a goal (the
    grasp) and at the end of the run, each a cube of at least 1 m."""
    pts = np.vstack(list(log.frame_positions.values()))
    pts = pts[np.isfinite(pts).all(axis=1)]
    if not len(pts) or np.max(pts.max(axis=0) - pts.min(axis=0)) <= DRIVE_EXTENT:
        return []
    goals = phase_goals(log)
    first = goals[0][1].split(", ")[0] if goals else None
    last = {name: k for name, _, k, _ in _phase_rows(log)}
    at = [(f"near the hands at the end of '{first}'", last[first])] if first else []
    at.append(("near the hands at the end", len(log) - 1))
    out = []
    for title, k in at:
        hands = np.array([p[k] for p in log.frame_positions.values() if np.isfinite(p[k]).all()])
        if not len(hands):
            continue
        half = max(0.5, float(np.max(hands.max(0) - hands.min(0))) / 2 + 0.3)
        centre = (hands.max(0) + hands.min(0)) / 2
        out.append((title, centre - half, centre + half))
    return out


def _legend(fig: Figure, log: RunLog, objects: Mapping[str, ObjectSpec], carried: bool) -> None:
    """One legend for the figure, below the panels: phases by colour, executed/reference by
    line style, start and goal markers, the kinds of object drawn."""
    handles = [Line2D([], [], color=c, lw=2, label=name) for name, _, _, c in _phases(log)]
    handles += [
        Line2D([], [], color="k", lw=1.8, label="executed"),
        Line2D([], [], color="k", lw=0.9, ls="--", label="reference"),
        Line2D([], [], color="k", marker="o", ls="", label="start (hand named)"),
        Line2D([], [], color="k", marker="x", ls="", mew=2, label="goal (phase named)"),
    ]
    if any(o.obstacle for o in objects.values()):
        handles.append(Patch(color=OBSTACLE, alpha=0.6, label="obstacle"))
    if any(not o.obstacle for o in objects.values()):
        handles.append(Patch(color=PROP, alpha=0.6, label="prop"))
    if carried:
        handles.append(Patch(color=CARRIED, alpha=0.8, label="carried object"))
    fig.legend(
        handles=handles, loc="lower center", ncol=min(len(handles), 6), fontsize=8, frameon=False
    )


def hand_paths(
    log: RunLog,
    out: Path,
    objects: Mapping[str, ObjectSpec] = {},
    carried: Mapping[str, np.ndarray] | None = None,
    title: str = "",
    limits: Sequence[tuple[float, float]] | None = None,
) -> Path:
    """:func:`hand_paths_figure` written to ``out`` (PNG)."""
    return _save(hand_paths_figure(log, objects, carried, title, limits), out)


def hand_paths_figure(
    log: RunLog,
    objects: Mapping[str, ObjectSpec] = {},
    carried: Mapping[str, np.ndarray] | None = None,
    title: str = "",
    limits: Sequence[tuple[float, float]] | None = None,
) -> Figure:
    """Executed (solid) and reference (dashed) hand paths in 3-D, one colour per phase, each
    phase's goal marked and named. ``carried`` maps an object name to its (N, 4, 4) poses:
    drawn at five instants. ``limits`` zooms the main panel. Panels beside it: a top view
    near the obstacles (if any), and near the hands at the first goal and at the end when
    the hands travel more than :data:`DRIVE_EXTENT` (equal axes over a drive would squash
    the grasp to a few pixels)."""
    carried = {k: v for k, v in (carried or {}).items() if not np.allclose(v[0], v[-1])}
    obstacles = [o for o in objects.values() if o.obstacle]
    windows = _windows(log) if limits is None else []
    n = 1 + bool(obstacles) + len(windows)
    fig = _figure(figsize=(max(8.0, 5.2 * n), 6.3))
    _margins(fig, 0.2, 0.2, 1.0, 0.55, wspace=0.15)
    ax = fig.add_subplot(1, n, 1, projection="3d")
    _draw_paths3d(ax, log)
    _draw_objects3d(ax, objects, carried)
    if limits is not None:
        ax.set_xlim(*limits[0])
        ax.set_ylim(*limits[1])
        ax.set_zlim(*limits[2])
    else:
        _equal_limits(ax, *_bounds(log, objects))
    _axes3d(ax, "hand paths" + (" (whole run)" if windows else ""))
    k = 2
    if obstacles:
        _obstacle_detail(fig.add_subplot(1, n, k), log, obstacles)
        k += 1
    for name, lo, hi in windows:
        zoom = fig.add_subplot(1, n, k, projection="3d")
        _draw_paths3d(zoom, log, (lo, hi))
        _draw_objects3d(zoom, objects, carried, (lo, hi))
        _equal_limits(zoom, lo, hi, pad=0.0)
        _axes3d(zoom, name)
        k += 1
    _legend(fig, log, objects, bool(carried))
    fig.suptitle(title or "hand trajectories", fontsize=11)
    return fig


def _obstacle_detail(ax, log: RunLog, obstacles: list[ObjectSpec]) -> None:
    """Top view around the obstacles: paths, obstacles (and their margin), clearances."""
    centers = np.array([o.position for o in obstacles])
    reach = max(max(o.radius, *(np.asarray(o.size) / 2)) for o in obstacles) + 0.15
    lo, hi = centers[:, :2].min(0) - reach, centers[:, :2].max(0) + reach
    for hand, pos_all in log.frame_positions.items():
        inside = np.all((pos_all[:, :2] >= lo) & (pos_all[:, :2] <= hi), axis=1)
        if not inside.any():
            continue
        # blank the points outside the window (masking would join distant points)
        pos = np.where(inside[:, None], pos_all, np.nan)
        ref = np.where(inside[:, None], log.reference_positions[hand], np.nan)
        for _, first, last, color in _phase_rows(log):
            steps = _joined(first, last, len(log))
            ax.plot(pos[steps, 0], pos[steps, 1], lw=2, color=color)
            ax.plot(ref[steps, 0], ref[steps, 1], ls="--", lw=1, color=color)
    for o in obstacles:
        c = np.asarray(o.position)
        if o.kind == "box":
            w, d = o.size[0] / 2, o.size[1] / 2
            ax.add_patch(Rectangle((c[0] - w, c[1] - d), 2 * w, 2 * d, color=OBSTACLE, alpha=0.5))
        else:
            ax.add_patch(Circle(c[:2], o.radius, color=OBSTACLE, alpha=0.5))
            if o.margin:
                ax.add_patch(Circle(c[:2], o.radius + o.margin, color=OBSTACLE, fill=False, ls=":"))
        ax.text(c[0], c[1], o.name, fontsize=7, ha="center")
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    _title(ax, "top view near the obstacles (dotted: avoidance margin)")
    _plain(ax)


# ---------------------------------------------------------------------- joint velocities
def plotted_groups(log: RunLog) -> list[str]:
    """The joint groups of :func:`joint_velocities`: every group of the robot, those of the
    paper's figures (left arm, right arm, waist, wheels) first."""
    present = list(log.meta.get("groups", {}))
    first = [g for g in ("left_arm", "right_arm", "waist", "wheels") if g in present]
    return first + [g for g in present if g not in first]


def _shade_phases(axes: Sequence, log: RunLog) -> None:
    """Each phase's span lightly shaded in its colour on every axes, a dotted line at each
    boundary."""
    for _, t0, t1, color in _phases(log):
        for ax in axes:
            ax.axvspan(t0, t1, color=color, alpha=0.07, lw=0)
            ax.axvline(t0, color="0.6", lw=0.8, ls=":")


def _phase_labels(ax, log: RunLog, width_in: float, fontsize: float = 7.0) -> None:
    """Phase names above ``ax`` (``width_in`` inches wide), each centred on its span in its
    colour, in as many rows as it takes for no two to overlap (a label's width estimated at
    0.6 em a character)."""
    t_lo, t_hi = ax.get_xlim()
    per_inch = (t_hi - t_lo) / width_in
    ends: list[float] = []  # the right end (s) of the last label in each row
    for name, t0, t1, color in _phases(log):
        half = (0.6 * fontsize / 72 * len(name) / 2 + 0.05) * per_inch
        mid = min(max((t0 + t1) / 2, t_lo + half), t_hi - half)
        row = next((i for i, end in enumerate(ends) if mid - half > end), len(ends))
        if row == len(ends):
            ends.append(mid + half)
        else:
            ends[row] = mid + half
        where = offset_copy(
            ax.get_xaxis_transform(), fig=ax.figure, y=3 + row * (fontsize + 4), units="points"
        )
        ax.text(
            mid,
            1.0,
            name,
            transform=where,
            fontsize=fontsize,
            color=color,
            ha="center",
            va="bottom",
            fontweight="bold",
            clip_on=False,
        )


def joint_velocities(log: RunLog, out: Path, title: str = "") -> Path:
    """:func:`joint_velocities_figure` written to ``out`` (PNG)."""
    return _save(joint_velocities_figure(log, title), out)


def joint_velocities_figure(log: RunLog, title: str = "") -> Figure:
    """Actuated velocities per joint group against time (rad/s; wheels in rad/s), one
    panel per group with its legend outside on the right (never over the data); phases
    shaded in their colours and named above the first panel."""
    groups = plotted_groups(log)
    names = log.meta.get("actuated_joints", [])
    width, panel = 11.0, 1.9
    fig = _figure(figsize=(width, panel * len(groups) + 1.3))
    left, right = 0.85, 2.6
    _margins(fig, left, right, 0.5, 0.8, hspace=0.12)
    axes = np.atleast_1d(fig.subplots(len(groups), 1, sharex=True))
    for ax, g in zip(axes, groups, strict=True):
        idx = log.group_indices(g)
        t, u = thin(log.t, log.u[:, idx])
        for j, i in enumerate(idx):
            ax.plot(t, u[:, j], lw=0.9, label=names[i] if i < len(names) else str(i))
        ax.set_ylabel(f"{g.replace('_', ' ')}\n(rad/s)", fontsize=9)
        _plain(ax)
        ax.legend(
            fontsize=7,
            loc="upper left",
            bbox_to_anchor=(1.01, 1.0),
            borderaxespad=0,
            ncol=1 if len(idx) <= 10 else 2,
            frameon=False,
        )
    axes[-1].set_xlabel("time (s)")
    axes[-1].xaxis.set_major_locator(MaxNLocator(10))
    axes[0].set_xlim(float(log.t[0]), float(log.t[-1] + log.dt))
    _shade_phases(axes, log)
    _phase_labels(axes[0], log, width - left - right)
    fig.suptitle(title or "joint velocities", fontsize=11)
    return fig


# ---------------------------------------------------------------------- arm energy
def arm_energy(log: RunLog, out: Path, title: str = "") -> Path:
    """:func:`arm_energy_figure` written to ``out`` (PNG)."""
    return _save(arm_energy_figure(log, title), out)


def arm_energy_figure(log: RunLog, title: str = "") -> Figure:
    """Per arm (a row each, every panel titled with its arm): gravity, spring and total
    energy (J) over time; the arm angle (rad) over time where it is defined, broken where
    it wraps between -pi and pi; the spring energy against the arm angle, coloured by time
    (its colour bar in s). Phases shaded in their colours; one legend below the panels."""
    arms = list(log.arms)
    fig = _figure(figsize=(14, 3.3 * len(arms) + 0.9))
    _margins(fig, 0.75, 0.55, 0.85, 0.6, wspace=0.28, hspace=0.5)
    axes = fig.subplots(len(arms), 3, squeeze=False)
    for row, arm in zip(axes, arms, strict=True):
        _arm_row(fig, row, log, arm)
    handles = [Line2D([], [], color=c, lw=2, label=label) for label, c in ENERGY_TERMS.items()]
    handles += [Patch(color=c, alpha=0.15, label=f"phase {name}") for name, _, _, c in _phases(log)]
    fig.legend(
        handles=handles, loc="lower center", ncol=min(len(handles), 8), fontsize=8, frameon=False
    )
    fig.suptitle(title or "arm potential energy", fontsize=11)
    return fig


ENERGY_TERMS = {"gravity f_g": "#1f77b4", "spring f_e": "#ff7f0e", "total f_p": "k"}
"""The arm energy's terms as :func:`arm_energy` draws them: label and colour (plain text:
mathtext's fonts cost a tenth of a second to load in a fresh process)."""


def _arm_row(fig: Figure, row: Sequence, log: RunLog, arm: str) -> None:
    """One arm's three panels of :func:`arm_energy`."""
    tr = log.arms[arm]
    t, terms = thin(log.t, np.column_stack([tr.gravity, tr.spring, tr.energy]))
    for j, color in enumerate(ENERGY_TERMS.values()):
        row[0].plot(t, terms[:, j], color=color, lw=1 if j == 2 else 1.5)
    row[0].set_ylabel("energy (J)")
    ok = tr.rho >= ARM_ANGLE_MIN_RHO
    angle = np.where(ok, tr.arm_angle, np.nan)
    ta, angle = break_wraps(*thin(log.t, angle))
    row[1].plot(ta, angle, color="#9467bd")
    row[1].set_ylabel("arm angle (rad)")
    _shade_phases(row[:2], log)
    for ax, what in zip(row[:2], ("energy", "arm angle"), strict=True):
        ax.set_xlabel("time (s)")
        _title(ax, f"{arm} arm: {what}")
    ts, pts = thin(log.t[ok], np.column_stack([tr.arm_angle[ok], tr.spring[ok]]))
    sc = row[2].scatter(
        pts[:, 0], pts[:, 1], s=3, c=ts, cmap="viridis", vmin=float(log.t[0]), vmax=float(log.t[-1])
    )
    bar = fig.colorbar(sc, ax=row[2], pad=0.02, fraction=0.05)
    bar.set_label("time (s)", fontsize=8)
    bar.ax.tick_params(labelsize=7)
    row[2].set_xlabel("arm angle (rad)")
    row[2].set_ylabel("spring energy (J)")
    _title(row[2], f"{arm} arm: spring energy against the arm angle")
    for ax in row:
        _plain(ax)


def _title(ax, text: str) -> None:
    """A panel title at a fixed height (an automatic one measures the ticks below it:
    a tenth of a second a figure)."""
    ax.set_title(text, fontsize=9, y=1.01)


def _plain(ax, bins: int = 5) -> None:
    """A 2-D panel's grid and at most about ``bins`` ticks an axis (each tick is several
    artists to lay out and draw)."""
    ax.xaxis.set_major_locator(MaxNLocator(bins))
    ax.yaxis.set_major_locator(MaxNLocator(bins))
    ax.grid(alpha=0.3)
    ax.tick_params(labelsize=8)


# ---------------------------------------------------------------------- physics
def physics(
    log: RunLog, physics: Mapping, out: Path, title: str = "", kinematic: RunLog | None = None
) -> Path:
    """:func:`physics_figure` written to ``out`` (PNG)."""
    return _save(physics_figure(log, physics, title, kinematic), out)


def physics_figure(
    log: RunLog, physics: Mapping, title: str = "", kinematic: RunLog | None = None
) -> Figure:
    """A physics run over time: each hand's distance to its reference (mm; a kinematic run
    of the same scenario dashed beside it, if given) and the closed chain's error; the peak
    torque of each joint group as a share of its limit; each grasp's force and the squeeze
    (N). Phases shaded and named."""
    groups = plotted_groups(log)
    fig = _figure(figsize=(11.0, 7.6))
    _margins(fig, 0.85, 2.6, 0.5, 0.8, hspace=0.15)
    ax_err, ax_tau, ax_f = fig.subplots(3, 1, sharex=True)
    for name in log.frame_positions:
        e = np.linalg.norm(log.frame_positions[name] - log.reference_positions[name], axis=1)
        ax_err.plot(*thin(log.t, 1e3 * e), lw=0.9, label=f"{name} (physics)")
        if kinematic is not None and name in kinematic.frame_positions:
            k = kinematic.frame_positions[name] - kinematic.reference_positions[name]
            ax_err.plot(
                *thin(kinematic.t, 1e3 * np.linalg.norm(k, axis=1)),
                lw=0.8,
                ls="--",
                label=f"{name} (kinematic)",
            )
    if "closed_chain" in log.task_errors:
        chain = np.linalg.norm(log.task_errors["closed_chain"][:, :3], axis=1)
        ax_err.plot(*thin(log.t, 1e3 * chain), lw=0.9, color="k", label="closed chain")
    ax_err.set_ylabel("tracking error\n(mm)", fontsize=9)
    for g in groups:
        if g in physics["group_torque"]:
            share = (physics["group_torque"][g] / physics["group_limit"][g]).max(axis=1)
            ax_tau.plot(*thin(log.t, 100 * share), lw=0.9, label=g.replace("_", " "))
    ax_tau.axhline(100, color="#d62728", lw=0.8, ls=":")
    ax_tau.set_ylabel("peak torque\n(% of limit)", fontsize=9)
    for (obj, frame), force in physics["grasp_force"].items():
        ax_f.plot(*thin(log.t, np.linalg.norm(force, axis=1)), lw=0.9, label=f"{obj} at {frame}")
    for obj, s in physics.get("squeeze", {}).items():
        ax_f.plot(*thin(log.t, s), lw=0.9, color="k", label=f"{obj} squeeze")
    ax_f.set_ylabel("grasp force\n(N)", fontsize=9)
    for ax in (ax_err, ax_tau, ax_f):
        _plain(ax)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(
                fontsize=7,
                loc="upper left",
                bbox_to_anchor=(1.01, 1.0),
                borderaxespad=0,
                frameon=False,
            )
    ax_f.set_xlabel("time (s)")
    ax_err.set_xlim(float(log.t[0]), float(log.t[-1] + log.dt))
    _shade_phases((ax_err, ax_tau, ax_f), log)
    _phase_labels(ax_err, log, 11.0 - 0.85 - 2.6)
    fig.suptitle(title or "physics run (MuJoCo)", fontsize=11)
    return fig
