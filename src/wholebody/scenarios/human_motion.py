"""The motion test on people: does the robot hold its elbow as the person did?

For each recorded trial (shoulder, elbow and wrist of one arm of a person, lab frame), the
person's wrist relative to their shoulder is mapped onto the robot's arm with the paper's
mapping (the directions of the upper arm and the forearm kept, the robot's lengths:
:func:`wholebody.humanlike.mapping.map_to_robot`; canonical arm axes x forward, y medial,
z up, the base's axes on the robot), and the robot's wrist centre relative to its shoulder
centre is driven along it (:class:`~wholebody.tasks.RelativePositionTask`, the paper's PI
law) by each controller; the other hand holds its pose. Only the wrist is prescribed, as the
person's was relative to their shoulder: the elbow, the waist, the clavicle and the base are
the controller's choice. The robot's arm angle is compared with the person's frame by frame
(both in the canonical convention of :mod:`wholebody.arm.angle`), over the frames where
both are defined (the elbow at least ``min_rho`` off a shoulder-wrist line that is not
vertical).

Each trial starts with a 2 s approach from the robot's home posture to the path's first point
(not scored), then follows the trial at its own timing.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wholebody.arm.angle import DOWN, arm_angle
from wholebody.control import Controller
from wholebody.errors import DataError
from wholebody.humanlike.evaluation import cluster_bootstrap
from wholebody.humanlike.mapping import lab_to_canonical, map_to_robot
from wholebody.humanlike.recordings import Recording
from wholebody.planning.trajectory import (
    MinimumJerkTrajectory,
    Trajectory,
    TrajectoryArrays,
)
from wholebody.presets import HUMAN_LIKE, PaperWeights, paper_stack
from wholebody.robot import ArmChain, Robot
from wholebody.solvers import ProjectionSolver
from wholebody.tasks import ArmPotentialEnergy, FrameTask, RelativePositionTask

__all__ = [
    "CONTROLLERS",
    "MotionScores",
    "ParticipantScores",
    "PathTrajectory",
    "TrialResult",
    "compare_arm_angles",
    "evaluate",
    "held_out_arm_angle_models",
    "run_trial",
    "write_report",
]

APPROACH_S = 2.0
"""The unscored approach from the home posture to the path's first point (s)."""


class PathTrajectory(Trajectory):
    """A position path sampled at increasing times (piecewise linear; velocity the slope of
    each segment; orientation the identity: only positions are tracked)."""

    def __init__(self, times: np.ndarray, positions: np.ndarray) -> None:
        t = np.asarray(times, dtype=float)
        p = np.asarray(positions, dtype=float)
        if t.ndim != 1 or p.shape != (t.size, 3) or t.size < 2 or np.any(np.diff(t) <= 0):
            raise DataError("PathTrajectory: times (N,) increasing and positions (N, 3)")
        self._t, self._p = t - t[0], p
        self._v = np.diff(p, axis=0) / np.diff(self._t)[:, None]

    @property
    def duration(self) -> float:
        return float(self._t[-1])

    def _evaluate(self, times: np.ndarray) -> TrajectoryArrays:
        k = np.clip(np.searchsorted(self._t, times, side="right") - 1, 0, self._t.size - 2)
        frac = (times - self._t[k])[:, None]
        zeros = np.zeros((times.size, 3))
        return TrajectoryArrays(
            times=times,
            positions=self._p[k] + frac * self._v[k],
            rotations=np.broadcast_to(np.eye(3), (times.size, 3, 3)).copy(),
            linear_velocities=self._v[k].copy(),
            angular_velocities=zeros,
            linear_accelerations=zeros.copy(),
            angular_accelerations=zeros.copy(),
        )


@dataclass
class TrialResult:
    """One trial under one controller: the person's and the robot's arm angles on the scored
    frames (rad), the waist's travel (rad, summed over its joints) and the wrist's tracking
    error (m, its median and largest over the trial: the arm's velocity limits can leave a
    fast stretch of a trial behind for a moment)."""

    participant: str
    trial: str
    human: np.ndarray
    robot: np.ndarray
    waist_travel: float
    wrist_error_m: float
    wrist_error_median_m: float = 0.0


@dataclass
class ParticipantScores:
    """One participant's scores under one controller, each with its 95 % interval over
    resamples of the participant's trials (:func:`compare_arm_angles`)."""

    alpha_rms_deg: float
    alpha_rms_deg_interval: tuple[float, float]
    waist_travel_rad: float
    """Summed over the participant's trials (rad)."""
    waist_travel_rad_per_trial: float
    waist_travel_rad_per_trial_interval: tuple[float, float]
    trials: int

    def as_dict(self) -> dict[str, object]:
        return {
            "alpha_rms_deg": self.alpha_rms_deg,
            "alpha_rms_deg_interval": list(self.alpha_rms_deg_interval),
            "waist_travel_rad": self.waist_travel_rad,
            "waist_travel_rad_per_trial": self.waist_travel_rad_per_trial,
            "waist_travel_rad_per_trial_interval": list(self.waist_travel_rad_per_trial_interval),
            "trials": self.trials,
        }


@dataclass
class MotionScores:
    """A controller's scores over trials (see :func:`compare_arm_angles`): the arm angle's
    rms and the waist's travel together, over everyone (intervals: participants resampled)
    and per participant (intervals: their trials resampled)."""

    alpha_rms_deg: float
    alpha_rms_deg_by_participant: dict[str, float]
    waist_travel_rad: float
    frames: int
    wrist_error_mm: float
    wrist_error_median_mm: float = 0.0
    alpha_rms_deg_interval: tuple[float, float] = (math.nan, math.nan)
    waist_travel_rad_per_trial: float = math.nan
    waist_travel_rad_per_trial_interval: tuple[float, float] = (math.nan, math.nan)
    participants: dict[str, ParticipantScores] = field(default_factory=dict)
    trials: list[TrialResult] = field(default_factory=list, repr=False)

    def as_dict(self) -> dict[str, object]:
        return {
            "alpha_rms_deg": self.alpha_rms_deg,
            "alpha_rms_deg_interval": list(self.alpha_rms_deg_interval),
            "alpha_rms_deg_by_participant": self.alpha_rms_deg_by_participant,
            "waist_travel_rad": self.waist_travel_rad,
            "waist_travel_rad_per_trial": self.waist_travel_rad_per_trial,
            "waist_travel_rad_per_trial_interval": list(self.waist_travel_rad_per_trial_interval),
            "participants": {p: sc.as_dict() for p, sc in self.participants.items()},
            "frames": self.frames,
            "wrist_error_mm_max": self.wrist_error_mm,
            "wrist_error_mm_median": self.wrist_error_median_mm,
        }


def _robot_arm(robot: Robot, side: str) -> ArmChain:
    for arm in robot.arms.values():
        if arm.side == side:
            return arm
    raise DataError(f"robot {robot.name!r} has no {side} arm for the recordings' {side} arms")


def defined(S: np.ndarray, E: np.ndarray, W: np.ndarray, min_rho: float) -> np.ndarray:
    """Per frame, whether the arm angle is well defined: the elbow at least ``min_rho`` (m)
    off the shoulder-wrist line, that line times the sine of its angle to the vertical."""
    u = W - S
    u = u / np.linalg.norm(u, axis=-1, keepdims=True)
    a = E - S
    d = a - np.sum(a * u, axis=-1, keepdims=True) * u
    sin_vertical = np.linalg.norm(np.cross(u, DOWN), axis=-1)
    return np.linalg.norm(d, axis=-1) * sin_vertical >= min_rho


def robot_wrist_path(arm: ArmChain, rec: Recording) -> np.ndarray:
    """The person's wrist relative to their shoulder, mapped onto the robot's arm, in the
    robot's base axes (T, 3) (m)."""
    S, E, W = (
        lab_to_canonical(v - rec.shoulder, rec.side) for v in (rec.shoulder, rec.elbow, rec.wrist)
    )
    _, W_R = map_to_robot(S, E, W, arm.upper_arm_length, arm.forearm_length)
    medial = 1.0 if arm.side == "right" else -1.0  # canonical y (medial) in the base's axes
    return W_R * np.array([1.0, medial, 1.0])


def run_trial(
    robot: Robot,
    rec: Recording,
    weights: PaperWeights | None,
    *,
    stiffness: object = None,
    arm_angle_model: object = None,
    min_rho: float = 0.02,
    dt: float = 0.01,
) -> TrialResult:
    """Drive the robot's wrist along one trial with the paper's stack of ``weights`` (None:
    the plain pseudo-inverse) and collect the arm angles on the scored frames."""
    arm = _robot_arm(robot, "right" if rec.side == "R" else "left")
    other = next((a for a in robot.arms.values() if a is not arm), None)
    if other is None:
        raise DataError(
            f"the motion test drives one arm and holds the other: robot {robot.name!r} has one arm"
        )
    q0 = robot.home()
    path = robot_wrist_path(arm, rec)
    wrist = RelativePositionTask(
        robot, arm.shoulder, arm.wrist, axes=robot.base_frame, kp=20.0, ki=5.0, name="wrist"
    )
    hold = FrameTask(robot, other.tool, kp=20.0, name="other_hand")
    hold.set_target(robot.frame_pose(q0, other.tool))
    stack = paper_stack(
        robot,
        [wrist, hold],
        objectives=weights is not None,
        weights=weights or PaperWeights(),
        stiffness=stiffness,
        arm_angle_model=arm_angle_model,
    )
    monitor = ArmPotentialEnergy(robot, arm, 0.0)
    start = np.eye(4)
    start[:3, 3] = wrist.relative_position(robot.update(q0))
    goal = start.copy()
    goal[:3, 3] = path[0]
    approach = MinimumJerkTrajectory(start, goal, APPROACH_S)
    ctrl = Controller(
        robot, stack, ProjectionSolver(), dt=dt, monitors=[monitor], references={wrist: approach}
    )
    first = ctrl.run(q0, APPROACH_S)
    ctrl = Controller(
        robot,
        stack,
        ProjectionSolver(),
        dt=dt,
        monitors=[monitor],
        references={wrist: PathTrajectory(rec.time_s, path)},
    )
    log = ctrl.run(
        np.asarray(first.meta["final_q"]), float(rec.time_s[-1] - rec.time_s[0]), u0=first.u[-1]
    )
    t = rec.time_s - rec.time_s[0]
    k = np.clip(np.round(t / dt).astype(int), 0, len(log) - 1)
    human = arm_angle(rec.shoulder, rec.elbow, rec.wrist, rec.side_sign)
    robot_alpha = log.arms[arm.name].arm_angle[k]
    scored = defined(rec.shoulder, rec.elbow, rec.wrist, min_rho) & (
        log.arms[arm.name].rho[k] >= min_rho
    )
    waist = robot.groups.get("waist")
    travel = 0.0
    if waist is not None:
        travel = float(np.abs(np.diff(log.joint_positions[:, waist.indices], axis=0)).sum())
    err = np.linalg.norm(log.task_errors["wrist"], axis=1)
    return TrialResult(
        rec.participant,
        rec.name,
        human[scored],
        robot_alpha[scored],
        travel,
        float(err.max()),
        float(np.median(err)),
    )


def compare_arm_angles(trials: Sequence[TrialResult]) -> MotionScores:
    """rms of the robot's arm angle against the person's (deg; differences wrapped into
    (-180, 180]) over all scored frames, and the waist's travel (rad: summed, and per trial),
    with their 95 % intervals (participants resampled), and the same per participant (their
    trials resampled)."""
    if not trials:
        raise DataError("compare_arm_angles: no trials")
    diffs = [
        np.degrees(np.remainder(t.robot - t.human + math.pi, 2 * math.pi) - math.pi) for t in trials
    ]
    every = np.concatenate(diffs)
    by: dict[str, list[int]] = {}
    for k, t in enumerate(trials):
        by.setdefault(t.participant, []).append(k)
    square = np.array([float(np.sum(d * d)) for d in diffs])
    count = np.array([d.size for d in diffs], dtype=float)
    travel = np.array([t.waist_travel for t in trials])
    people = {p: np.array(ks) for p, ks in sorted(by.items())}
    per = {p: _participant(square[ks], count[ks], travel[ks]) for p, ks in people.items()}
    clusters = list(people.values())  # (the participants: resampled whole)
    return MotionScores(
        alpha_rms_deg_interval=_ratio_interval(
            [square[ks].sum() for ks in clusters], [count[ks].sum() for ks in clusters], True
        ),
        alpha_rms_deg=float(np.sqrt(np.mean(every**2))) if every.size else math.nan,
        alpha_rms_deg_by_participant={p: sc.alpha_rms_deg for p, sc in per.items()},
        waist_travel_rad=float(travel.sum()),
        waist_travel_rad_per_trial=float(travel.mean()),
        waist_travel_rad_per_trial_interval=_ratio_interval(
            [travel[ks].sum() for ks in clusters], [float(ks.size) for ks in clusters]
        ),
        participants=per,
        frames=int(every.size),
        wrist_error_mm=float(max(t.wrist_error_m for t in trials) * 1e3),
        wrist_error_median_mm=float(np.median([t.wrist_error_median_m for t in trials]) * 1e3),
        trials=list(trials),
    )


def _participant(square: np.ndarray, count: np.ndarray, travel: np.ndarray) -> ParticipantScores:
    """One participant's scores from their trials' summed squared differences (deg^2),
    frame counts and waist travels (rad); intervals over resamples of the trials."""
    total = float(count.sum())
    return ParticipantScores(
        alpha_rms_deg=math.sqrt(float(square.sum()) / total) if total else math.nan,
        alpha_rms_deg_interval=_ratio_interval(square, count, True),
        waist_travel_rad=float(travel.sum()),
        waist_travel_rad_per_trial=float(travel.mean()),
        waist_travel_rad_per_trial_interval=_ratio_interval(travel, np.ones(travel.size)),
        trials=int(travel.size),
    )


def _ratio_interval(
    num: Sequence[float] | np.ndarray, den: Sequence[float] | np.ndarray, root: bool = False
) -> tuple[float, float]:
    """95 % bootstrap interval of ``sum(num) / sum(den)`` (its square root where ``root``)
    over resamples, with replacement, of the clusters ``(num_i, den_i)``
    (:func:`~wholebody.humanlike.evaluation.cluster_bootstrap`): participants (an rms over all
    frames is ``sqrt(sum d^2 / sum n)``; a mean travel per trial is ``sum travel / trials``),
    or one participant's trials. Why whole clusters: frames of one trial, or trials of one
    person, are not independent of each other. One cluster: its own value, twice."""
    num, den = np.asarray(num, dtype=float), np.asarray(den, dtype=float)

    def ratio(idx: np.ndarray) -> float:
        total = float(den[idx].sum())
        r = float(num[idx].sum()) / total if total else math.nan
        return math.sqrt(r) if root else r

    if num.size < 2:
        value = ratio(np.arange(num.size))
        return value, value
    _, low, high = cluster_bootstrap(ratio, np.arange(num.size))
    return low, high


def evaluate(
    robot: Robot,
    recordings: Sequence[Recording],
    controllers: Mapping[str, PaperWeights | None],
    *,
    stiffness: object = None,
    arm_angle_model: object = None,
) -> dict[str, MotionScores]:
    """Every trial under every controller (``name -> weights``; None: the pseudo-inverse).

    ``arm_angle_model``: the human arm angle the controllers with a pull use (None: the
    shipped one), or a mapping participant -> model (a model trained without that
    participant: a held-out test; every participant of ``recordings`` must be in it).
    """
    if isinstance(arm_angle_model, Mapping):
        missing = sorted({r.participant for r in recordings} - set(arm_angle_model))
        if missing:
            raise DataError(f"evaluate: no arm-angle model for the participants {missing}")
    models = arm_angle_model if isinstance(arm_angle_model, Mapping) else None
    return {
        name: compare_arm_angles(
            [
                run_trial(
                    robot,
                    rec,
                    w,
                    stiffness=stiffness,
                    arm_angle_model=models[rec.participant]
                    if models is not None
                    else arm_angle_model,
                )
                for rec in recordings
            ]
        )
        for name, w in controllers.items()
    }


def held_out_arm_angle_models(
    recordings: Sequence[Recording], *, n_records: int = 20000, only: Sequence[str] | None = None
) -> dict[str, object]:
    """Per participant of ``recordings`` (or of ``only``), the arm-angle network trained as
    the shipped one (:func:`wholebody.humanlike.arm_angle_fit.train_arm_angle`, its default
    settings, on ``n_records`` records of every recording) without that participant's
    records: the models of a held-out motion test. Each network's ``meta["participants"]``
    lists those it was trained on. Requires the ``learn`` extra (PyTorch)."""
    from wholebody.humanlike.arm_angle_data import arm_angle_records
    from wholebody.humanlike.arm_angle_fit import train_arm_angle

    records = arm_angle_records(recordings, n_records=n_records)
    people = sorted({r.participant for r in recordings})
    if len(people) < 2:
        raise DataError(f"held-out models need >= 2 participants, got {people}")
    unknown = sorted(set(only or ()) - set(people))
    if unknown:
        raise DataError(f"held-out models: no recordings of {', '.join(unknown)}")
    models: dict[str, object] = {}
    for person in people if only is None else sorted(set(only)):
        train = records.subset(records.participant != person)
        net = train_arm_angle(train.p, train.alpha).network
        net.meta["participants"] = sorted(set(train.participant.tolist()))
        models[person] = net
    return models


CONTROLLERS: dict[str, PaperWeights | None] = {
    "pseudo_inverse": None,
    "paper": PaperWeights(),
    "human_arm_angle": HUMAN_LIKE,
}
"""The controllers the test compares: the plain pseudo-inverse, the paper's stack (its spring
and learned stiffness), and the human-like preset (:data:`~wholebody.presets.HUMAN_LIKE`: the
paper's stack with the spring replaced by a level of :class:`~wholebody.tasks.HumanArmAngleTask`
below the wrist, rate 10 1/s, and the waist dear in the velocity metric; the pull as an
objective of ``H`` instead, ``human_arm_angle = w``, stays further from people at every
weight measured: benchmarks/README.md, "Human motion")."""


def write_report(
    scores: Mapping[str, MotionScores], out: Path, meta: Mapping[str, object]
) -> dict[str, Path]:
    """``humanlike.json`` (per controller its scores, and ``meta``) and ``humanlike.png``
    (the robot's arm angle against the person's, one panel per controller) in ``out``."""
    from wholebody.files import save_figure, write_json

    out.mkdir(parents=True, exist_ok=True)
    data = {"controllers": {n: s.as_dict() for n, s in scores.items()}, **meta}
    written = {"json": write_json(out / "humanlike.json", data, indent=2)}
    written["plot"] = save_figure(_figure(scores), out / "humanlike.png", dpi=100)
    return written


def _figure(scores: Mapping[str, MotionScores]):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(4.0 * len(scores), 4.0))
    for i, (name, sc) in enumerate(scores.items()):
        ax = fig.add_subplot(1, len(scores), i + 1)
        h = np.degrees(np.concatenate([t.human for t in sc.trials]))
        r = np.degrees(np.concatenate([t.robot for t in sc.trials]))
        step = max(1, h.size // 4000)  # a few thousand points tell the picture
        ax.scatter(h[::step], r[::step], s=2, alpha=0.3)
        ax.plot([-60, 120], [-60, 120], "k--", lw=0.8, label="robot = person")
        ax.set(
            xlim=(-60, 120),
            ylim=(-60, 120),
            xlabel="person's arm angle (deg)",
            ylabel="robot's arm angle (deg)",
            title=f"{name}: {sc.alpha_rms_deg:.1f} deg rms",
        )
        ax.legend(loc="upper left", fontsize=8)
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.13, top=0.9, wspace=0.3)
    return fig
