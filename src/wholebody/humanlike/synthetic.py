"""SYNTHETIC standing reaches for the paper's protocol (no public recording covers it).

Everything this module makes is **synthetic**: recordings carry ``source = "synthetic"``,
participant ids ``SYN01``, ``SYN02``, ... and a ``note`` saying how they were made.

The protocol (Niu et al. 2024, Section 2)
-----------------------------------------
Each virtual participant reaches with the right arm, one trial per target:

* **standing** block, 27 targets: 3 parallel vertical (frontal) planes 15 cm apart, a 3 x 3
  grid with 15 cm spacing on each, the lowest row 1.40 m above the floor (rows 1.40, 1.55,
  1.70 m). The grid is centred in front of the reaching shoulder (columns 15 cm medial, in
  line, 15 cm lateral); the farthest plane is at ``0.85 (L1 + L2 + hand)`` in front of the
  shoulder (a choice: the paper gives no distance). Each reach starts from the hanging arm
  (wrist at 0.99 (L1 + L2) from the shoulder, 7 deg forward of the vertical).
* **tabletop** block, 9 targets, seated as in the real recordings (so that the two overlap):
  a 3 x 3 grid with 15 cm spacing, 20/35/50 cm in front of the shoulder, same columns, on a
  table 0.185 x stature below the shoulder (0.32 m for 1.75 m), objects 5 cm high. Each
  reach starts with the wrist resting on the table edge, 15 cm in front of the shoulder.

The wrist centre aims at ``target - hand * unit(target - shoulder)`` (the grasp point is at
the knuckles, one hand length beyond the wrist), pulled back to 0.95 (L1 + L2) from the
shoulder when out of reach (counted in :class:`SyntheticSummary`). The shoulder is fixed.

Motion and posture
------------------
* Wrist: a straight minimum-jerk path ``p0 + (p1 - p0)(10 s^3 - 15 s^4 + 6 s^5)``, ``s = t/T``
  (Flash & Hogan 1985), duration ``T = 1.875 D / v_peak`` with peak speed ``v_peak`` =
  0.65 m/s (the bundled real reaches peak at 0.6-0.7 m/s), sampled at 30 Hz (Kinect).
* Elbow: on its circle at the arm angle of Kim et al.'s criterion with the calibrated target
  and noise (:mod:`wholebody.humanlike.arm_angle_model`, :data:`CALIBRATED`): per-participant,
  per-block and per-trial offsets and a within-trial Ornstein-Uhlenbeck process, seeded.
* Anthropometrics: de Leva (1996), "Adjustments to Zatsiorsky-Seluyanov's segment inertia
  parameters", J. Biomech. 29(9):1223-1230, Table 4 (mean female / male: stature, segment
  lengths, mass fractions, centres of mass), lengths scaled by stature;
  shoulder height 0.818 x stature and shoulder width 0.259 x stature (Drillis & Contini,
  via Winter 2009).

The lab frame is that of the recordings (+x the participant's right, +y forward, +z up,
origin on the floor between the feet).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from wholebody.humanlike.arm_angle_model import CALIBRATED, ArmAngleModel, elbow_on_circle
from wholebody.humanlike.mapping import CANONICAL_SIDE, canonical_to_lab
from wholebody.humanlike.recordings import Recording

__all__ = [
    "DEFAULT_PARTICIPANTS",
    "DE_LEVA",
    "SyntheticSummary",
    "VirtualParticipant",
    "generate_participant",
    "generate_synthetic",
    "minimum_jerk",
    "protocol_targets",
]

# de Leva (1996) Table 4: mean stature (m) and body mass (kg) of the sample, segment lengths
# (m: upper arm SJC-EJC, forearm EJC-WJC, hand WJC-MET3), mass (fraction of body mass) and
# centre of mass (fraction of the length from the proximal end).
DE_LEVA = {
    "F": {
        "stature": 1.735,
        "mass": 61.9,
        "upper_arm": 0.2751,
        "forearm": 0.2643,
        "hand": 0.0780,
        "upper_arm_mass": 0.0255,
        "forearm_mass": 0.0138,
        "hand_mass": 0.0056,
        "upper_arm_com": 0.5754,
        "forearm_com": 0.4559,
    },
    "M": {
        "stature": 1.741,
        "mass": 73.0,
        "upper_arm": 0.2817,
        "forearm": 0.2689,
        "hand": 0.0862,
        "upper_arm_mass": 0.0271,
        "forearm_mass": 0.0162,
        "hand_mass": 0.0061,
        "upper_arm_com": 0.5772,
        "forearm_com": 0.4574,
    },
}
SHOULDER_HEIGHT = 0.818  # x stature
SHOULDER_WIDTH = 0.259  # x stature
SAMPLE_RATE = 30.0  # Hz
PEAK_SPEED = 0.65  # m/s
ROWS = (1.40, 1.55, 1.70)  # m above the floor
SPACING = 0.15  # m
MAX_REACH = 0.95  # fraction of L1 + L2
FAR_PLANE = 0.85  # fraction of L1 + L2 + hand
TABLE_DROP = 0.185  # x stature, table surface below the shoulder (seated)
OBJECT_HEIGHT = 0.05  # m
TABLE_ROWS = (0.20, 0.35, 0.50)  # m in front of the shoulder


@dataclass(frozen=True)
class VirtualParticipant:
    """A synthetic person: de Leva's mean segment lengths scaled by ``stature`` (m)."""

    id: str
    sex: str
    stature: float

    def _scaled(self, key: str) -> float:
        row = DE_LEVA[self.sex]
        return row[key] * self.stature / row["stature"]

    @property
    def upper_arm(self) -> float:
        return self._scaled("upper_arm")

    @property
    def forearm(self) -> float:
        return self._scaled("forearm")

    @property
    def hand(self) -> float:
        return self._scaled("hand")

    @property
    def shoulder(self) -> np.ndarray:
        """Right shoulder centre in the lab frame (m)."""
        return np.array([0.5 * SHOULDER_WIDTH * self.stature, 0.0, SHOULDER_HEIGHT * self.stature])


# Three women and three men at the sexes' mean stature and +-1 sd (about 0.065 m).
DEFAULT_PARTICIPANTS = (
    VirtualParticipant("SYN01", "F", 1.565),
    VirtualParticipant("SYN02", "M", 1.705),
    VirtualParticipant("SYN03", "F", 1.630),
    VirtualParticipant("SYN04", "M", 1.770),
    VirtualParticipant("SYN05", "F", 1.695),
    VirtualParticipant("SYN06", "M", 1.835),
)


@dataclass
class SyntheticSummary:
    """Counts of what the generator did."""

    participants: int = 0
    trials: int = 0
    frames: int = 0
    clamped_targets: int = 0
    notes: list[str] = field(default_factory=list)


def minimum_jerk(p0: np.ndarray, p1: np.ndarray, duration: float, t: np.ndarray) -> np.ndarray:
    """Minimum-jerk straight path (len(t), 3) from ``p0`` to ``p1`` in ``duration`` s."""
    s = np.clip(np.asarray(t, dtype=float) / duration, 0.0, 1.0)[:, None]
    return p0 + (p1 - p0) * (10 * s**3 - 15 * s**4 + 6 * s**5)


def protocol_targets(p: VirtualParticipant) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """``(task, start wrist, target)`` of the 36 trials, shoulder-relative canonical axes
    (x forward, y medial, z up; m). ``target`` is the grasp point, not yet the wrist."""
    S_lab = p.shoulder
    reach = p.upper_arm + p.forearm
    far = FAR_PLANE * (reach + p.hand)
    columns = (SPACING, 0.0, -SPACING)  # medial, in line, lateral
    out = []
    tilt = np.radians(7.0)
    hang = 0.99 * reach * np.array([np.sin(tilt), 0.0, -np.cos(tilt)])
    for plane in (far - 2 * SPACING, far - SPACING, far):
        for row in ROWS:
            for col in columns:
                out.append(("standing", hang, np.array([plane, col, row - S_lab[2]])))
    table = -TABLE_DROP * p.stature
    rest = np.array([0.15, 0.0, table + 0.03])
    for fwd in TABLE_ROWS:
        for col in columns:
            out.append(("tabletop", rest, np.array([fwd, col, table + OBJECT_HEIGHT])))
    return out


def generate_participant(
    p: VirtualParticipant,
    rng: np.random.Generator,
    model: ArmAngleModel = CALIBRATED,
    summary: SyntheticSummary | None = None,
) -> list[Recording]:
    """The 36 synthetic trials of one virtual participant (right arm, lab frame)."""
    summary = summary if summary is not None else SyntheticSummary()
    L1, L2, reach = p.upper_arm, p.forearm, p.upper_arm + p.forearm
    S_lab = p.shoulder
    zero = np.zeros(3)
    e_part = rng.normal(0.0, model.sd_participant)
    e_block = {
        "standing": rng.normal(0.0, model.sd_block),
        "tabletop": rng.normal(0.0, model.sd_block),
    }
    counters = {"standing": 0, "tabletop": 0}
    recs = []
    note = (
        "SYNTHETIC (wholebody.humanlike.synthetic): minimum-jerk wrist path, elbow from Kim et "
        "al. 2012's arm-angle criterion calibrated on UE_ADLdatabase reaches, de Leva 1996 "
        f"anthropometrics; {p.sex}, stature {p.stature:.3f} m"
    )
    for task, start, target in protocol_targets(p):
        counters[task] += 1
        direction = target / np.linalg.norm(target)
        goal = target - p.hand * direction
        dist = float(np.linalg.norm(goal))
        if dist > MAX_REACH * reach:
            goal = goal * (MAX_REACH * reach / dist)
            summary.clamped_targets += 1
        D = float(np.linalg.norm(goal - start))
        T = max(0.6, 1.875 * D / PEAK_SPEED)
        t = np.arange(0.0, T + 1e-9, 1.0 / SAMPLE_RATE)
        W = minimum_jerk(start, goal, T, t)
        S = np.broadcast_to(zero, W.shape)
        alpha = (
            model.predict(S, W, L1, L2, p.stature)
            + e_part
            + e_block[task]
            + rng.normal(0.0, model.sd_trial)
            + model.within_trial_noise(rng, t)
        )
        E = elbow_on_circle(S, W, L1, L2, alpha, CANONICAL_SIDE)
        recs.append(
            Recording(
                t,
                np.tile(S_lab, (len(t), 1)),
                S_lab + canonical_to_lab(E, "R"),
                S_lab + canonical_to_lab(W, "R"),
                p.id,
                task,
                "R",
                counters[task],
                "synthetic",
                None,
                note,
            )
        )
        summary.trials += 1
        summary.frames += len(t)
    summary.participants += 1
    return recs


def generate_synthetic(
    participants: Sequence[VirtualParticipant] = DEFAULT_PARTICIPANTS,
    *,
    seed: int = 0,
    model: ArmAngleModel = CALIBRATED,
    summary: SyntheticSummary | None = None,
) -> list[Recording]:
    """All synthetic trials (36 per participant), reproducible from ``seed``.

    Each participant draws from its own stream ``default_rng([seed, i])``, so adding
    participants does not change the others' data.
    """
    out: list[Recording] = []
    for i, p in enumerate(participants):
        out += generate_participant(p, np.random.default_rng([seed, i]), model, summary)
    return out
