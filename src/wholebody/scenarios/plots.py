"""The paper's figures from a run log (PNG, headless: figures are drawn without pyplot, so
importing this module changes no matplotlib state).

* :func:`hand_paths`: executed hand paths in 3-D with their references, the obstacles,
  the props and a carried object at a few instants (Figs. 9, 10, 15);
* :func:`joint_velocities`: actuated velocities per group, left arm, right arm, waist and
  wheels first (Figs. 12, 17), then the robot's other groups;
* :func:`arm_energy`: per arm, gravity and spring energy over time, the arm angle over time
  and the spring energy against the arm angle (Fig. 13).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Rectangle

from wholebody.control.log import RunLog
from wholebody.control.metrics import ARM_ANGLE_MIN_RHO
from wholebody.files import save_figure
from wholebody.scenarios.spec import ObjectSpec

__all__ = ["arm_energy", "hand_paths", "joint_velocities"]

COLORS = {"right_tool": "#1f77b4", "left_tool": "#d62728"}


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
    ax, obj: ObjectSpec, pose: np.ndarray | None = None, color="0.5", alpha=0.6
) -> None:
    c = np.asarray(obj.position) if pose is None else pose[:3, 3]
    R = np.eye(3) if pose is None else pose[:3, :3]
    if obj.kind == "box":
        for e in _box_edges(c, np.asarray(obj.size), R):
            ax.plot(*e.T, color=color, alpha=alpha, lw=1)
    elif obj.kind == "cylinder":
        th = np.linspace(0, 2 * np.pi, 40)
        for z in (-obj.height / 2, obj.height / 2):
            ring = c + np.column_stack(
                [obj.radius * np.cos(th), obj.radius * np.sin(th), np.full_like(th, z)]
            )
            ax.plot(*ring.T, color=color, alpha=alpha, lw=1)
        for a in th[::5]:
            p = c + np.array([obj.radius * np.cos(a), obj.radius * np.sin(a), 0.0])
            ax.plot(
                [p[0]] * 2,
                [p[1]] * 2,
                [p[2] - obj.height / 2, p[2] + obj.height / 2],
                color=color,
                alpha=alpha,
                lw=0.8,
            )
    else:
        u, v = np.mgrid[0 : 2 * np.pi : 20j, 0 : np.pi : 10j]
        ax.plot_wireframe(
            c[0] + obj.radius * np.cos(u) * np.sin(v),
            c[1] + obj.radius * np.sin(u) * np.sin(v),
            c[2] + obj.radius * np.cos(v),
            color=color,
            alpha=alpha,
            lw=0.5,
        )


def hand_paths(
    log: RunLog,
    out: Path,
    objects: Mapping[str, ObjectSpec] = {},
    carried: Mapping[str, np.ndarray] | None = None,
    title: str = "",
    limits: Sequence[tuple[float, float]] | None = None,
) -> Path:
    """Executed (solid) and reference (dashed) hand paths in 3-D. ``carried`` maps an object
    name to its (N, 4, 4) poses: drawn at five instants. ``limits`` zooms the axes."""
    obstacles = [o for o in objects.values() if o.obstacle]
    fig = Figure(figsize=(13 if obstacles else 7.5, 6.5))
    ax = fig.add_subplot(1, 2 if obstacles else 1, 1, projection="3d")
    for name, pos in log.frame_positions.items():
        color = COLORS.get(name)
        ref = log.reference_positions[name]
        (line,) = ax.plot(*pos.T, color=color, lw=2, label=f"{name} executed")
        ax.plot(*ref.T, color=line.get_color(), lw=1, ls="--", label=f"{name} reference")
        ax.scatter(*pos[0], color=line.get_color(), marker="o", s=20)
        ax.scatter(*ref[-1], color=line.get_color(), marker="x", s=40)
    for obj in objects.values():
        _draw_object(ax, obj, color="#d62728" if obj.obstacle else "0.45")
    for name, poses in (carried or {}).items():
        if name in objects and not np.allclose(poses[0], poses[-1]):
            for k in np.linspace(0, len(poses) - 1, 5).astype(int):
                _draw_object(ax, objects[name], poses[k], color="#2ca02c", alpha=0.8)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    if limits is not None:
        ax.set_xlim(*limits[0])
        ax.set_ylim(*limits[1])
        ax.set_zlim(*limits[2])
    else:
        pts = np.vstack([p for p in log.frame_positions.values()])
        mid, half = (pts.max(0) + pts.min(0)) / 2, (pts.max(0) - pts.min(0)).max() / 2 + 0.1
        for setter, m in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), mid, strict=True):
            setter(m - half, m + half)
    ax.legend(loc="upper left", fontsize=7)
    ax.set_title(title or "hand trajectories")
    if obstacles:
        _obstacle_detail(fig.add_subplot(1, 2, 2), log, obstacles)
    fig.tight_layout()
    save_figure(fig, out, dpi=120)
    return out


def _obstacle_detail(ax, log: RunLog, obstacles: list[ObjectSpec]) -> None:
    """Top view around the obstacles: paths, obstacles (and their margin), clearances."""
    centers = np.array([o.position for o in obstacles])
    reach = max(max(o.radius, *(np.asarray(o.size) / 2)) for o in obstacles) + 0.15
    lo, hi = centers[:, :2].min(0) - reach, centers[:, :2].max(0) + reach
    for name, pos in log.frame_positions.items():
        ref = log.reference_positions[name]
        inside = np.all((pos[:, :2] >= lo) & (pos[:, :2] <= hi), axis=1)
        if not inside.any():
            continue
        # blank the points outside the window (masking would join distant points)
        pos = np.where(inside[:, None], pos, np.nan)
        ref = np.where(inside[:, None], ref, np.nan)
        (line,) = ax.plot(
            pos[:, 0], pos[:, 1], lw=2, color=COLORS.get(name), label=f"{name} executed"
        )
        ax.plot(
            ref[:, 0],
            ref[:, 1],
            ls="--",
            lw=1,
            color=line.get_color(),
            label=f"{name} reference",
        )
    for o in obstacles:
        c = np.asarray(o.position)
        if o.kind == "box":
            w, d = o.size[0] / 2, o.size[1] / 2
            ax.add_patch(Rectangle((c[0] - w, c[1] - d), 2 * w, 2 * d, color="#d62728", alpha=0.5))
        else:
            ax.add_patch(Circle(c[:2], o.radius, color="#d62728", alpha=0.5))
            if o.margin:
                ax.add_patch(
                    Circle(c[:2], o.radius + o.margin, color="#d62728", fill=False, ls=":")
                )
        ax.text(c[0], c[1], o.name, fontsize=7, ha="center")
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title("top view near the obstacles (dotted: avoidance margin)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)


def plotted_groups(log: RunLog) -> list[str]:
    """The joint groups of :func:`joint_velocities`: every group of the robot, those of the
    paper's figures (left arm, right arm, waist, wheels) first."""
    present = list(log.meta.get("groups", {}))
    first = [g for g in ("left_arm", "right_arm", "waist", "wheels") if g in present]
    return first + [g for g in present if g not in first]


def joint_velocities(log: RunLog, out: Path, title: str = "") -> Path:
    """Actuated velocities per joint group against time (rad/s; wheels in rad/s)."""
    groups = plotted_groups(log)
    fig = Figure(figsize=(8, 2.2 * len(groups)))
    axes = fig.subplots(len(groups), 1, sharex=True)
    axes = np.atleast_1d(axes)
    names = log.meta.get("actuated_joints", [])
    for ax, g in zip(axes, groups, strict=True):
        for i in log.group_indices(g):
            ax.plot(log.t, log.u[:, i], lw=1, label=names[i] if i < len(names) else str(i))
        ax.set_ylabel(f"{g.replace('_', ' ')}\n(rad/s)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=6, ncol=4, loc="upper right")
    for name, (t0, _) in log.meta.get("phases", {}).items():
        for ax in axes:
            ax.axvline(t0, color="0.6", lw=0.8, ls=":")
        axes[0].text(t0, axes[0].get_ylim()[1], f" {name}", fontsize=7, va="top")
    axes[-1].set_xlabel("time (s)")
    fig.suptitle(title or "joint velocities")
    fig.tight_layout()
    save_figure(fig, out, dpi=120)
    return out


def arm_energy(log: RunLog, out: Path, title: str = "") -> Path:
    """Per arm: gravity, spring and total energy (J) over time; arm angle (rad) over time,
    where defined; spring energy against the arm angle."""
    arms = list(log.arms)
    fig = Figure(figsize=(13, 3.2 * len(arms)))
    axes = fig.subplots(len(arms), 3, squeeze=False)
    for row, arm in zip(axes, arms, strict=True):
        tr = log.arms[arm]
        row[0].plot(log.t, tr.gravity, label="gravity $f_g$")
        row[0].plot(log.t, tr.spring, label="spring $f_e$")
        row[0].plot(log.t, tr.energy, label="total $f_p$", color="k", lw=1)
        row[0].set_ylabel(f"{arm} arm energy (J)")
        row[0].legend(fontsize=7)
        ok = tr.rho >= ARM_ANGLE_MIN_RHO
        angle = np.where(ok, tr.arm_angle, np.nan)
        row[1].plot(log.t, angle, color="#9467bd")
        row[1].set_ylabel("arm angle (rad)")
        row[2].scatter(tr.arm_angle[ok], tr.spring[ok], s=3, c=log.t[ok], cmap="viridis")
        row[2].set_xlabel("arm angle (rad)")
        row[2].set_ylabel("spring energy (J)")
        for ax in row[:2]:
            ax.set_xlabel("time (s)")
            ax.grid(alpha=0.3)
        row[2].grid(alpha=0.3)
    fig.suptitle(title or "arm potential energy")
    fig.tight_layout()
    save_figure(fig, out, dpi=110)
    return out
