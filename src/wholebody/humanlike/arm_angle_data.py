"""Records of the arm angle people choose: ``(p, alpha_h)`` from recordings (numpy only).

Each frame of each recording goes through

1. the canonical arm axes (shoulder-relative, x forward, y medial, z up;
   :func:`~wholebody.humanlike.mapping.lab_to_canonical`, left arms mirrored),
2. the **person's** arm angle ``alpha_h = arm_angle(0, E - S, W - S, CANONICAL_SIDE)``
   (:mod:`wholebody.arm.angle`: 0 elbow lowest, > 0 outwards) and the normalised wrist
   ``p = (W - S) / (L1 + L2)``, ``L1``, ``L2`` the trial's median upper-arm and forearm
   lengths as recorded (so ``|p| <= 1`` up to soft-tissue artefact; the robot queries with
   its own lengths, :func:`wholebody.arm.normalised_wrist`),
3. the frame rules of the stiffness labels (:func:`~wholebody.humanlike.labels.frame_rules`)
   on the person's posture: ``straight`` (elbow < 4 cm from the S-W line), ``vertical``
   (S-W within 20 deg of the vertical: alpha's reference is undefined), ``forearm``
   (forearm length > 2 cm from its trial median); a frame any rule flags is dropped,

and then each trial gives the same number of records, evenly spaced in time over its kept
frames, as the stiffness dataset does (:func:`~wholebody.humanlike.dataset.trial_quotas`,
:func:`~wholebody.humanlike.dataset.evenly_spaced`). Every trial, and so every participant
(all did the same 40 trials), weighs alike.

The records also keep what the baselines need: the wrist in metres, the arm's lengths, the
stature (Kim et al.'s model, :mod:`~wholebody.humanlike.arm_angle_model`) and a hand
direction (unit vector from the wrist to the index fingertip, canonical axes; NaN where the
recording has no fingertip).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from wholebody.errors import DataError
from wholebody.humanlike.arm_angle_model import ArmAngleModel, kim_arm_angle
from wholebody.humanlike.dataset import evenly_spaced, trial_quotas
from wholebody.humanlike.labels import arm_geometry, frame_rules
from wholebody.humanlike.mapping import CANONICAL_SIDE, lab_to_canonical
from wholebody.humanlike.recordings import Participant, Recording

__all__ = ["ArmAngleRecords", "arm_angle_records", "kim_predictions"]

_ARRAYS = (
    "p",
    "alpha",
    "wrist",
    "upper_arm",
    "forearm",
    "stature",
    "hand",
    "time_s",
    "participant",
    "task",
    "trial",
)


@dataclass
class ArmAngleRecords:
    """Records of the person's arm angle and where the wrist was (module docstring).

    Attributes
    ----------
    p
        (N, 3) normalised wrist ``(W - S) / (L1 + L2)``, canonical axes, dimensionless.
    alpha
        (N,) the person's arm angle, rad.
    wrist
        (N, 3) ``W - S``, canonical axes, m.
    upper_arm, forearm
        (N,) the trial's median recorded lengths, m.
    stature
        (N,) m (NaN for a participant not in the table).
    hand
        (N, 3) unit hand direction (wrist to index fingertip), canonical axes; NaN without
        a fingertip marker.
    time_s
        (N,) s in the trial.
    participant, task, trial
        (N,) ids; ``trial`` is ``{participant}_{task}_{side}{n}``.
    counts
        Per task: trials, frames, frames each rule flagged, kept, records.
    """

    p: np.ndarray
    alpha: np.ndarray
    wrist: np.ndarray
    upper_arm: np.ndarray
    forearm: np.ndarray
    stature: np.ndarray
    hand: np.ndarray
    time_s: np.ndarray
    participant: np.ndarray
    task: np.ndarray
    trial: np.ndarray
    counts: dict[str, dict[str, int]] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.alpha)

    def participants(self) -> list[str]:
        return sorted(set(self.participant.tolist()))

    def subset(self, mask: np.ndarray) -> ArmAngleRecords:
        """The records ``mask`` (bool or index array) selects."""
        return ArmAngleRecords(**{k: getattr(self, k)[mask] for k in _ARRAYS}, counts=self.counts)


def _frames(rec: Recording, stature: float) -> dict[str, np.ndarray]:
    """Every frame of one recording as record arrays, with the rules' masks (``rules``)."""
    E = lab_to_canonical(rec.elbow - rec.shoulder, rec.side)
    W = lab_to_canonical(rec.wrist - rec.shoulder, rec.side)
    geo = arm_geometry(np.zeros_like(E), E, W, CANONICAL_SIDE)
    fl = rec.forearm_lengths()
    L1 = float(np.median(rec.upper_arm_lengths()))
    L2 = float(np.median(fl))
    hand = np.full_like(W, np.nan)
    if rec.fingertip is not None:
        d = lab_to_canonical(rec.fingertip - rec.wrist, rec.side)
        n = np.linalg.norm(d, axis=1, keepdims=True)
        hand = np.divide(d, n, out=hand, where=n > 0)
    n_frames = rec.n_frames
    return {
        "p": W / (L1 + L2),
        "alpha": geo.alpha,
        "wrist": W,
        "upper_arm": np.full(n_frames, L1),
        "forearm": np.full(n_frames, L2),
        "stature": np.full(n_frames, stature),
        "hand": hand,
        "time_s": rec.time_s,
        "rules": frame_rules(geo, np.abs(fl - L2)),  # type: ignore[dict-item]
    }


def arm_angle_records(
    recordings: Sequence[Recording],
    participants: Mapping[str, Participant] | None = None,
    *,
    n_records: int = 20000,
) -> ArmAngleRecords:
    """The records of ``recordings`` (module docstring): about ``n_records``, every trial
    alike. ``participants`` gives the statures (for Kim et al.'s baseline; NaN without).

    Raises
    ------
    DataError
        No recording, ``n_records < 1``, or no frame passes the rules.
    """
    if not recordings:
        raise DataError("arm_angle_records: no recordings")
    if n_records < 1:
        raise DataError(f"arm_angle_records: n_records must be >= 1, got {n_records}")
    people = participants or {}
    counts: dict[str, dict[str, int]] = {}
    trials = []
    for rec in recordings:
        person = people.get(rec.participant)
        frames = _frames(rec, person.stature if person else float("nan"))
        drop = np.zeros(rec.n_frames, dtype=bool)
        c = counts.setdefault(rec.task, {})
        for name, mask in frames.pop("rules").items():  # type: ignore[union-attr]
            c[name] = c.get(name, 0) + int(mask.sum())
            drop |= mask
        c["trials"] = c.get("trials", 0) + 1
        c["frames"] = c.get("frames", 0) + rec.n_frames
        c["dropped"] = c.get("dropped", 0) + int(drop.sum())
        c["kept"] = c.get("kept", 0) + int((~drop).sum())
        if (~drop).any():
            trials.append((rec, frames, np.flatnonzero(~drop)))
    if not trials:
        raise DataError(
            f"no frame of the {len(recordings)} recording(s) passed the frame rules: {counts}"
        )
    parts: dict[str, list] = {k: [] for k in _ARRAYS}
    for (rec, frames, keep), q in zip(trials, trial_quotas(len(trials), n_records), strict=True):
        if q == 0:
            continue
        pick = evenly_spaced(keep, q)
        for k, v in frames.items():
            parts[k].append(v[pick])
        for k, v in (("participant", rec.participant), ("task", rec.task), ("trial", rec.name)):
            parts[k].append(np.full(len(pick), v))
        c = counts[rec.task]
        c["records"] = c.get("records", 0) + len(pick)
    arrays = {k: np.concatenate(v) for k, v in parts.items()}
    for k in ("participant", "task", "trial"):
        arrays[k] = arrays[k].astype(str)
    return ArmAngleRecords(**arrays, counts=counts)


def kim_predictions(records: ArmAngleRecords, model: ArmAngleModel) -> np.ndarray:
    """Kim et al.'s arm angle with ``model``'s head target and bias (rad) at every record,
    from the person's wrist, arm lengths and stature (the noise-free
    :meth:`~wholebody.humanlike.arm_angle_model.ArmAngleModel.predict`, vectorised over
    people)."""
    if not np.isfinite(records.stature).all():
        missing = sorted(set(records.participant[~np.isfinite(records.stature)].tolist()))
        raise DataError(f"Kim et al.'s model needs the stature of {', '.join(missing)}")
    S = np.zeros_like(records.wrist)
    target = records.stature[:, None] * np.asarray(model.target)
    return (
        kim_arm_angle(S, records.wrist, records.upper_arm, records.forearm, target, CANONICAL_SIDE)
        + model.bias
    )
