"""The run figures: phases told apart and goals named, panels near the hands over a drive,
legends off the data, phase labels apart, colour bars and arm-angle wraps, and the speed
measures (no layout engine, thinned traces)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from matplotlib.figure import Figure

from wholebody.control import RunLog
from wholebody.control.log import ArmTrace
from wholebody.scenarios import plots
from wholebody.scenarios.spec import ObjectSpec

DT = 0.01


def synthetic_log(
    phases: dict[str, tuple[np.ndarray, np.ndarray]],
    hands: int = 1,
    angle: np.ndarray | None = None,
) -> RunLog:
    """A log whose hands' references move along straight lines, one per phase ``name:
    (start, end)`` of 100 steps each (hands 0.3 m apart in y), executed 1 mm off; two arms,
    the arm angle ``angle`` (rad, default a slow sweep); 4 joints in 2 groups."""
    n_phase = 100
    refs, spans, t0 = [], {}, 0.0
    for name, (a, b) in phases.items():
        s = np.linspace(0.0, 1.0, n_phase)[:, None]
        refs.append(a + s * (b - a))
        spans[name] = [t0, t0 + n_phase * DT]
        t0 += n_phase * DT
    ref = np.vstack(refs)
    n = len(ref)
    t = np.arange(n) * DT
    names = ["right", "left"][:hands]
    ref_by = {h: ref + np.array([0.0, -0.3 * i, 0.0]) for i, h in enumerate(names)}
    angle = np.linspace(-1.0, 1.0, n) if angle is None else angle
    arm = ArmTrace(
        energy=np.sin(t) - 5,
        gravity=np.sin(t) - 5.2,
        spring=np.cos(t) ** 2 / 5,
        arm_angle=angle,
        stiffness=np.full(n, 0.1),
        rho=np.full(n, 0.1),
    )
    u = np.column_stack([np.sin(t * k) for k in range(1, 5)])
    u[n // 2, 0] = 9.0  # a one-step spike
    return RunLog(
        t=t,
        q=np.zeros((n, 4)),
        u=u,
        joint_positions=np.zeros((n, 4)),
        step_time=np.full(n, 1e-4),
        solve_time=np.full(n, 1e-4),
        status=np.zeros(n, dtype=int),
        limit_hit=np.zeros(n, dtype=bool),
        level_residuals=np.zeros((n, 1)),
        frame_positions={h: r + 0.001 for h, r in ref_by.items()},
        reference_positions=ref_by,
        arms={"left": arm, "right": arm},
        meta={
            "dt": DT,
            "phases": spans,
            "groups": {"left_arm": [0, 1], "wheels": [2, 3]},
            "actuated_joints": ["shoulder", "elbow", "wheel_a", "wheel_b"],
        },
    )


HOME = np.array([0.1, -0.47, 0.4])
REACHES = {
    "reach_1": (HOME, np.array([1.7, -0.45, 0.46])),
    "return_1": (np.array([1.7, -0.45, 0.46]), HOME),
    "reach_2": (HOME, np.array([1.7, -0.30, 0.76])),
    "return_2": (np.array([1.7, -0.30, 0.76]), HOME),
    "reach_3": (HOME, np.array([1.7, -0.55, 1.06])),
}
DRIVE = {
    "approach": (HOME, np.array([1.65, -0.27, 0.7])),
    "grasp": (np.array([1.65, -0.27, 0.7]), np.array([1.65, -0.27, 0.7])),
    "carry": (np.array([1.65, -0.27, 0.7]), np.array([-1.7, -6.9, 1.05])),
}


def texts(fig: Figure) -> list[str]:
    return [t.get_text() for ax in fig.axes for t in ax.texts]


def test_reaches_are_told_apart_and_goals_named():
    """reach_generalisation's three reaches: one colour per phase, each goal marked and named
    (the returns to one place share a label), start and goal markers in the legend."""
    log = synthetic_log(REACHES)
    goals = plots.phase_goals(log)
    assert [label for _, label, _ in goals] == [
        "reach_1",
        "return_1, return_2",
        "reach_2",
        "reach_3",
    ]
    fig = plots.hand_paths_figure(log)
    (ax,) = fig.axes
    colours = {line.get_color() for line in ax.lines if line.get_linestyle() == "-"}
    assert len(colours) == 5  # a colour for each phase
    assert {"reach_1", "reach_2", "reach_3"} <= {t.strip() for t in texts(fig)}
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    assert {"reach_1", "return_2", "start (hand named)", "goal (phase named)"} <= set(legend)


def test_a_drive_gets_panels_near_the_hands():
    """Equal axes over a 7 m drive squash the grasp: two more panels, near the hands at the
    first goal and at the end, each about a metre across."""
    log = synthetic_log(DRIVE, hands=2)
    fig = plots.hand_paths_figure(log, carried={})
    titles = [ax.get_title() for ax in fig.axes]
    assert titles == [
        "hand paths (whole run)",
        "near the hands at the end of 'approach'",
        "near the hands at the end",
    ]
    for ax in fig.axes[1:]:
        assert ax.get_xlim()[1] - ax.get_xlim()[0] < 1.5
    assert len(plots.hand_paths_figure(synthetic_log(REACHES)).axes) == 1  # no drive


def test_hand_paths_draw_objects_and_obstacles():
    """Props, obstacles and a carried object are drawn; obstacles add the top view."""
    log = synthetic_log(REACHES)
    objects = {
        "shelf": ObjectSpec(
            name="shelf", kind="box", position=(1.8, -0.2, 0.43), size=(0.3, 1.6, 0.03)
        ),
        "post": ObjectSpec(
            name="post",
            kind="cylinder",
            position=(1.7, -0.4, 0.6),
            radius=0.04,
            height=0.2,
            obstacle=True,
            margin=0.03,
        ),
    }
    fig = plots.hand_paths_figure(log, objects)
    assert len(fig.axes) == 2 and "top view" in fig.axes[1].get_title()
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "obstacle" in legend and "prop" in legend


def test_joint_velocity_legends_sit_outside_the_data():
    fig = plots.joint_velocities_figure(synthetic_log(DRIVE))
    fig.canvas.draw()
    for ax in fig.axes:
        legend = ax.get_legend()
        assert legend is not None
        assert legend.get_window_extent().x0 >= ax.get_window_extent().x1


def test_phase_labels_do_not_overlap():
    """grasp (1 s) between approach (5 s) and carry (20 s): the names are drawn apart."""
    log = synthetic_log(DRIVE)
    log.meta["phases"] = {"approach": [0.0, 1.0], "grasp": [1.0, 1.05], "carry": [1.05, 3.0]}
    fig = plots.joint_velocities_figure(log)
    fig.canvas.draw()
    boxes = [t.get_window_extent() for t in fig.axes[0].texts]
    assert [t.get_text() for t in fig.axes[0].texts] == ["approach", "grasp", "carry"]
    for a, b in itertools.combinations(boxes, 2):
        assert not a.overlaps(b)


def test_arm_energy_has_colour_bars_arm_names_and_no_wrap_jumps():
    """Each spring-energy scatter has a colour bar (time, s); every panel names its arm; an
    arm angle wrapping from pi to -pi is drawn broken at the wrap."""
    n = 500
    angle = np.concatenate([np.linspace(2.8, 3.1, n // 2), np.linspace(-3.1, -2.8, n - n // 2)])
    fig = plots.arm_energy_figure(synthetic_log(REACHES, angle=angle))
    panels = [ax for ax in fig.axes if ax.get_title()]
    bars = [ax for ax in fig.axes if ax.get_ylabel() == "time (s)"]
    assert len(panels) == 6 and len(bars) == 2
    for ax in panels:
        assert ax.get_title().split()[0] in ("left", "right")
    angle_axes = [ax for ax in panels if ax.get_title().endswith("arm angle")]
    (line,) = [line for line in angle_axes[0].lines if len(line.get_xdata()) > 2]  # not axvline
    y = np.asarray(line.get_ydata(), dtype=float)
    assert np.isnan(y).sum() == 1
    assert np.nanmax(np.abs(np.diff(y))) < np.pi  # no vertical jump across the axis


def test_break_wraps_and_thin():
    t = np.arange(6.0)
    tt, a = plots.break_wraps(t, np.array([3.0, 3.1, -3.1, -3.0, -3.1, 3.1]))
    assert np.isnan(a).sum() == 2 and len(tt) == 8 and np.all(np.diff(tt) > 0)
    x = np.linspace(0, 1, 10_000)
    y = np.sin(20 * x)
    y[5_000] = 7.0  # a one-sample spike
    y[7_000:7_100] = np.nan  # a gap
    tx, ty = plots.thin(x, y, n_max=1000)
    assert len(tx) <= 1100 and np.all(np.diff(tx) > 0)
    assert np.nanmax(ty) == 7.0 and np.isnan(ty).any()
    assert np.nanmin(ty) == pytest.approx(np.nanmin(y))
    _, y2 = plots.thin(x, np.column_stack([y, -y]), n_max=1000)
    assert y2.shape[1] == 2 and np.nanmin(y2[:, 1]) == -7.0


def test_figures_use_no_layout_engine(tmp_path, monkeypatch):
    """tight_layout draws a figure once more to measure it (a third of the time the
    figures took): the figures are laid out with fixed margins instead."""

    def refuse(*args, **kwargs):
        raise AssertionError("tight_layout called")

    monkeypatch.setattr(Figure, "tight_layout", refuse)
    log = synthetic_log(DRIVE, hands=2)
    plots.hand_paths(log, tmp_path / "hands.png")
    plots.joint_velocities(log, tmp_path / "jv.png")
    plots.arm_energy(log, tmp_path / "ae.png")
    for name in ("hands.png", "jv.png", "ae.png"):
        assert (tmp_path / name).read_bytes()[:4] == b"\x89PNG"
    for fig in (plots.hand_paths_figure(log), plots.arm_energy_figure(log)):
        assert fig.get_layout_engine() is None


def test_a_run_of_a_robot_without_arms_writes_its_figures_but_no_arm_energy(tmp_path):
    """A robot.toml without [arms] is valid: its run's figures are written, the arm-energy
    figure left out (it has nothing to draw), and nothing raises."""
    from types import SimpleNamespace

    from wholebody.scenarios.outputs import write_figures

    log = synthetic_log(DRIVE)
    log.arms.clear()
    spec = SimpleNamespace(title="", name="no_arms", objects={})
    run = SimpleNamespace(spec=spec, log=log, backend="pinv", object_poses={}, physics=None)
    files = write_figures(run, tmp_path)  # type: ignore[arg-type]
    assert set(files) == {"hands", "joint_velocities"}
    assert all(p.read_bytes()[:4] == b"\x89PNG" for p in files.values())
