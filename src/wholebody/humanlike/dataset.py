"""The stiffness dataset: (robot wrist position, k) records from human reaches.

Each frame of each recording goes through

1. the canonical arm axes (shoulder-relative, x forward, y medial, z up;
   :func:`~wholebody.humanlike.mapping.lab_to_canonical`, left arms mirrored),
2. the posture mapping to the robot's link lengths
   (:func:`~wholebody.humanlike.mapping.map_to_robot`),
3. the closed-form label ``k = A sin|alpha| / (pi - |alpha|)`` with the robot's masses and
   centres of mass (:func:`~wholebody.humanlike.labels.stiffness_labels`),
4. the frame rules (:func:`~wholebody.humanlike.labels.frame_rules`: ``straight``,
   ``vertical``, ``forearm``); a frame any rule flags is dropped,

and then each trial contributes the same number of records, evenly spaced in time over its
kept frames: ``n_records // n_trials`` (the first ``n_records % n_trials`` trials one more;
a trial with fewer kept frames gives all of them). So about ``n_records`` records (5000 by
default, like the paper) with every trial weighted alike.

File (``.npz``, no pickled objects)
-----------------------------------
``wrist`` (N, 3) robot wrist relative to the shoulder, canonical axes, m -- the model
input; ``k`` (N,) N m/rad; ``alpha`` (N,) rad, the robot's arm angle; ``amplitude`` (N,) N m;
``human_wrist`` (N, 3) the person's wrist, same axes, m; ``time_s`` (N,) s in the trial;
``source`` (N,) ``"real"``/``"synthetic"``; ``participant`` (N,) id; ``trial`` (N,) trial id
``{participant}_{task}_{side}{n}``; ``meta`` (0-d JSON string: robot and arm parameters,
rules and their drop counts, build settings, description).
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from wholebody.errors import DataError
from wholebody.files import read_npz, write_npz
from wholebody.humanlike.labels import (
    MAX_FOREARM_DEVIATION,
    MIN_ELBOW_OFFSET,
    MIN_TILT,
    frame_rules,
    stiffness_labels,
)
from wholebody.humanlike.mapping import ArmParameters, lab_to_canonical, map_to_robot
from wholebody.humanlike.recordings import Recording
from wholebody.resources import npz_path

__all__ = [
    "DEFAULT_TEST_PARTICIPANTS",
    "BuildReport",
    "StiffnessDataset",
    "build_dataset",
    "evenly_spaced",
    "label_recording",
    "trial_quotas",
]

# Held out from training, fixed before any model was fitted: two men and a woman of the real
# data spanning its statures (1.80, 1.575, 1.65 m). Synthetic participants are never held
# out: scores on them measure the generator, not people.
DEFAULT_TEST_PARTICIPANTS = ("ADL003", "ADL008", "ADL011")
FORMAT = "wholebody.stiffness_dataset/1"
_ARRAYS = (
    "wrist",
    "k",
    "alpha",
    "amplitude",
    "human_wrist",
    "time_s",
    "source",
    "participant",
    "trial",
)


@dataclass
class BuildReport:
    """Frame counts per source: ``frames`` seen, dropped by each rule (a frame may trip
    several), ``dropped`` in total, ``kept``, and ``records`` written."""

    counts: dict[str, dict[str, int]] = field(default_factory=dict)

    def add(self, source: str, key: str, n: int) -> None:
        c = self.counts.setdefault(source, {})
        c[key] = c.get(key, 0) + int(n)

    def summary(self) -> str:
        lines = []
        for src, c in sorted(self.counts.items()):
            rules = ", ".join(f"{r} {c.get(r, 0)}" for r in ("straight", "vertical", "forearm"))
            lines.append(
                f"{src}: {c.get('trials', 0)} trials, {c.get('frames', 0)} frames; dropped "
                f"{c.get('dropped', 0)} ({rules}); kept {c.get('kept', 0)}; records "
                f"{c.get('records', 0)}"
            )
        return "\n".join(lines)


@dataclass
class StiffnessDataset:
    """Records of (robot canonical wrist position, k) with their provenance (see module)."""

    wrist: np.ndarray
    k: np.ndarray
    alpha: np.ndarray
    amplitude: np.ndarray
    human_wrist: np.ndarray
    time_s: np.ndarray
    source: np.ndarray
    participant: np.ndarray
    trial: np.ndarray
    meta: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.k)

    def participants(self) -> list[str]:
        return sorted(set(self.participant.tolist()))

    def subset(self, mask: np.ndarray) -> StiffnessDataset:
        """The records where ``mask`` (bool or index array) selects."""
        arrays = {name: getattr(self, name)[mask] for name in _ARRAYS}
        return StiffnessDataset(**arrays, meta=dict(self.meta))

    def split(
        self, test_participants: Iterable[str] = DEFAULT_TEST_PARTICIPANTS
    ) -> tuple[StiffnessDataset, StiffnessDataset]:
        """(train, test) by participant: no participant is in both.

        Raises
        ------
        DataError
            A named test participant has no record, or nothing is left to train on.
        """
        test = sorted(set(test_participants))
        missing = [p for p in test if p not in set(self.participant.tolist())]
        if missing:
            raise DataError(
                f"split: participant(s) {', '.join(missing)} have no record in the dataset"
            )
        mask = np.isin(self.participant, test)
        if mask.all():
            raise DataError("split: every record belongs to a test participant")
        return self.subset(~mask), self.subset(mask)

    def save(self, path: str | Path) -> Path:
        """Write the dataset; returns the file written (``.npz`` appended if missing)."""
        arrays = {name: getattr(self, name) for name in _ARRAYS}
        meta = {"format": FORMAT, **self.meta}
        arrays["meta"] = np.array(json.dumps(meta, sort_keys=True))
        return write_npz(npz_path(path), arrays)

    @classmethod
    def load(cls, path: str | Path) -> StiffnessDataset:
        """Read a dataset file; raises :class:`DataError` naming the file and key at fault."""
        path = Path(path)
        z = read_npz(path, "stiffness dataset")
        missing = [k for k in (*_ARRAYS, "meta") if k not in z]
        if missing:
            raise DataError(f"{path}: missing key(s) {', '.join(missing)}")
        arrays = {k: z[k] for k in _ARRAYS}
        try:
            meta = json.loads(str(z["meta"]))
        except json.JSONDecodeError as exc:
            raise DataError(f"{path}: key 'meta' is not valid JSON ({exc})") from None
        if not isinstance(meta, dict):
            raise DataError(f"{path}: key 'meta' must be a JSON object, got {meta!r}")
        n = len(arrays["k"])
        for name, v in arrays.items():
            want = (n, 3) if name in ("wrist", "human_wrist") else (n,)
            if v.shape != want:
                raise DataError(f"{path}: key {name!r}: expected shape {want}, got {v.shape}")
        if meta.get("format") != FORMAT:
            raise DataError(f"{path}: format {meta.get('format')!r}, expected {FORMAT!r}")
        return cls(**arrays, meta=meta)


def label_recording(rec: Recording, params: ArmParameters) -> dict[str, np.ndarray]:
    """Map every frame of ``rec`` to the robot and label it (arrays over frames).

    Returns ``wrist`` (robot, canonical, shoulder-relative), ``human_wrist``, ``k``,
    ``alpha``, ``amplitude``, ``time_s`` and ``rules`` (the masks of
    :func:`~wholebody.humanlike.labels.frame_rules`).
    """
    E = lab_to_canonical(rec.elbow - rec.shoulder, rec.side)
    W = lab_to_canonical(rec.wrist - rec.shoulder, rec.side)
    S = np.zeros_like(E)
    E_R, W_R = map_to_robot(S, E, W, params.upper_arm, params.forearm)
    lab = stiffness_labels(S, E_R, W_R, params)
    fl = rec.forearm_lengths()
    rules = frame_rules(lab, np.abs(fl - np.median(fl)))
    return {
        "wrist": W_R,
        "human_wrist": W,
        "k": lab.k,
        "alpha": lab.alpha,
        "amplitude": lab.amplitude,
        "time_s": rec.time_s,
        "rules": rules,  # type: ignore[dict-item]
    }


def trial_quotas(n_trials: int, n_records: int) -> np.ndarray:
    """Records per trial: ``n_records // n_trials``, the first ``n_records % n_trials`` trials
    one more. Why: every trial weighs alike, whatever its length."""
    quota = np.full(n_trials, n_records // n_trials)
    quota[: n_records % n_trials] += 1
    return quota


def evenly_spaced(keep: np.ndarray, q: int) -> np.ndarray:
    """``q`` of the kept frame indices ``keep``, evenly spaced in time (all of them if there
    are no more than ``q``): ``keep[round(linspace(0, len(keep) - 1, q))]``."""
    if len(keep) <= q:
        return keep
    return keep[np.round(np.linspace(0, len(keep) - 1, q)).astype(int)]


def build_dataset(
    recordings: Sequence[Recording],
    params: ArmParameters,
    *,
    n_records: int = 5000,
    progress: bool = False,
    meta: dict | None = None,
) -> tuple[StiffnessDataset, BuildReport]:
    """Label, filter and subsample ``recordings`` into about ``n_records`` records (module
    docstring). ``meta`` is merged into the file's metadata."""
    if not recordings:
        raise DataError("build_dataset: no recordings")
    if n_records < 1:
        raise DataError(f"build_dataset: n_records must be >= 1, got {n_records}")
    report = BuildReport()
    labelled = []
    it = recordings
    if progress:
        from tqdm.auto import tqdm

        it = tqdm(recordings, desc="labelling frames", unit="trial")
    for rec in it:
        lab = label_recording(rec, params)
        drop = np.zeros(rec.n_frames, dtype=bool)
        for name, mask in lab["rules"].items():
            report.add(rec.source, name, int(mask.sum()))
            drop |= mask
        report.add(rec.source, "trials", 1)
        report.add(rec.source, "frames", rec.n_frames)
        report.add(rec.source, "dropped", int(drop.sum()))
        report.add(rec.source, "kept", int((~drop).sum()))
        labelled.append((rec, lab, np.flatnonzero(~drop)))
    trials = [t for t in labelled if len(t[2])]
    if not trials:
        raise DataError(
            f"no frame of the {len(labelled)} recording(s) passed the labelling "
            f"rules: {report.summary()}"
        )
    parts: dict[str, list] = {name: [] for name in _ARRAYS}
    for (rec, lab, keep), q in zip(trials, trial_quotas(len(trials), n_records), strict=True):
        if q == 0:
            continue
        pick = evenly_spaced(keep, q)
        for name in ("wrist", "k", "alpha", "amplitude", "human_wrist", "time_s"):
            parts[name].append(lab[name][pick])
        parts["source"].append(np.full(len(pick), rec.source))
        parts["participant"].append(np.full(len(pick), rec.participant))
        parts["trial"].append(np.full(len(pick), rec.name))
        report.add(rec.source, "records", len(pick))
    arrays = {name: np.concatenate(v) for name, v in parts.items()}
    for name in ("source", "participant", "trial"):
        arrays[name] = arrays[name].astype(str)
    info = {
        "robot": params.robot,
        "arm_parameters": asdict(params),
        "rules": {
            "straight": f"robot elbow < {MIN_ELBOW_OFFSET} m from the shoulder-wrist line",
            "vertical": f"shoulder-wrist line < {np.degrees(MIN_TILT):.0f} deg from vertical",
            "forearm": f"|person's forearm length - trial median| > {MAX_FOREARM_DEVIATION} m",
        },
        "counts": report.counts,
        "n_records": int(n_records),
        "frame": "robot wrist relative to the shoulder; x forward, y medial, z up; m",
        "units": {"k": "N m/rad", "alpha": "rad", "amplitude": "N m", "wrist": "m"},
        **(meta or {}),
    }
    return StiffnessDataset(**arrays, meta=info), report
