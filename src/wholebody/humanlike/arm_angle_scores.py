"""Scoring a model of the human arm angle on people it never saw (numpy only).

Leave-one-participant-out cross-validation: for each participant the model is trained on
the others' records and predicts the held-out participant's arm angles. The residual
``r = wrap(alpha - alpha_h)`` (rad, wrapped into (-pi, pi]) is scored per participant by
its root mean square, ``rms = sqrt(mean r^2)`` (deg), with a 95 % bootstrap interval that
resamples the participant's **trials** (frames of one trial are strongly correlated, so
frames are not resampled; :func:`~wholebody.humanlike.evaluation.cluster_bootstrap`). The
summary over participants is the rms over every held-out record (each participant has as
many records, so it weighs all alike), its interval from resampling **participants**, and
the paired difference of two models' rms under the same resamples.

Baselines, scored on the same records: ``constant`` (the training participants' mean arm
angle, refitted per fold: :class:`~wholebody.arm.human_arm_angle.ConstantArmAngle`) and
``kim`` (Kim et al.'s criterion with the shipped calibration
:data:`~wholebody.humanlike.arm_angle_model.CALIBRATED`, from each person's wrist, arm
lengths and stature; not refitted: it was calibrated on the forward/across reaches of nine of
the twelve participants, which favours it on them).

Spread of people about the model (rad), from the held-out residuals: with ``m_j`` and
``v_j`` the mean and variance of participant ``j``'s residuals::

    between = sqrt(mean_j m_j^2),   within = sqrt(mean_j v_j),   spread = sqrt(between^2 + within^2)

(``spread`` is the rms of all held-out residuals with participants weighted alike).

Between-person scatter of the arm angle (deg), the way the Kim calibration reports it
(:func:`~wholebody.humanlike.arm_angle_model.calibrate`, its ``sd_participant``): each
participant's mean residual (the mean over its trials of each trial's mean residual), and
the population standard deviation (``ddof = 0``) of those means over the participants. For
the network it is also given corrected for the sampling noise of each mean,
``sqrt(max(0, var_j(m_j) - mean_j(s_j^2 / n_j)))`` with ``s_j`` the sd of participant
``j``'s ``n_j`` trial means (method of moments for a random participant effect).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Protocol

import numpy as np

from wholebody.arm.human_arm_angle import ConstantArmAngle, HumanArmAngleModel
from wholebody.errors import DataError
from wholebody.humanlike.arm_angle_data import ArmAngleRecords, kim_predictions
from wholebody.humanlike.arm_angle_model import CALIBRATED, CALIBRATED_ON, ArmAngleModel, calibrate
from wholebody.humanlike.evaluation import cluster_bootstrap
from wholebody.humanlike.recordings import Participant, Recording

__all__ = [
    "MODELS",
    "between_person_scatter",
    "cross_validate",
    "kim_calibration_scatter",
    "paired_comparison",
    "spread_of",
    "wrap",
]

MODELS = ("network", "constant", "kim")
"""The rows of the scores: the model under test and the two baselines."""


class Predictor(Protocol):
    """Anything with ``predict(X) -> alpha (rad)`` for inputs (N, d)."""

    def predict(self, X: np.ndarray) -> np.ndarray: ...


def wrap(angle: np.ndarray) -> np.ndarray:
    """Angles (rad) wrapped into (-pi, pi]. Why: a residual of 359 deg is one of -1 deg."""
    return -np.remainder(np.pi - np.asarray(angle, dtype=float), 2.0 * np.pi) + np.pi


def _rms(r: np.ndarray) -> float:
    return float(np.sqrt(np.mean(r * r)))


def spread_of(residual: np.ndarray, participant: np.ndarray) -> tuple[float, float, float]:
    """``(spread, between, within)`` (rad) of residuals (module docstring)."""
    groups = [residual[participant == p] for p in np.unique(participant)]
    between = math.sqrt(float(np.mean([np.mean(g) ** 2 for g in groups])))
    within = math.sqrt(float(np.mean([np.var(g) for g in groups])))
    return math.hypot(between, within), between, within


def between_person_scatter(residual: np.ndarray, records: ArmAngleRecords) -> dict[str, float]:
    """Between-person sd (deg) of a residual (module docstring): ``sd`` (ddof 0, as the Kim
    calibration), ``sd_ddof1``, and ``sd_corrected`` for the sampling noise of the means."""
    means, noise = [], []
    for p in records.participants():
        sel = records.participant == p
        trials = np.unique(records.trial[sel])
        tm = np.array([np.mean(residual[sel & (records.trial == t)]) for t in trials])
        means.append(tm.mean())
        noise.append(np.var(tm, ddof=1) / len(tm) if len(tm) > 1 else 0.0)
    means_a = np.asarray(means)
    var = float(np.var(means_a))
    return {
        "sd": math.degrees(math.sqrt(var)),
        "sd_ddof1": math.degrees(float(np.std(means_a, ddof=1))) if len(means) > 1 else 0.0,
        "sd_corrected": math.degrees(math.sqrt(max(0.0, var - float(np.mean(noise))))),
        "participants": len(means),
    }


Fit = Callable[[ArmAngleRecords], HumanArmAngleModel | Predictor]
"""Trains a model on the training participants' records."""


def _held_out(
    records: ArmAngleRecords,
    fit: Fit,
    features: Callable[[ArmAngleRecords], np.ndarray],
    progress: bool,
) -> dict[str, np.ndarray]:
    """The network's and the constant baseline's predictions (rad) of every record by the
    model trained without its participant; the network predicts from ``features`` of the
    held-out records."""
    pred = {"network": np.empty(len(records)), "constant": np.empty(len(records))}
    people = records.participants()
    if len(people) < 2:
        raise DataError(f"cross-validation needs >= 2 participants, got {people}")
    it: Sequence[str] = people
    if progress:
        from tqdm.auto import tqdm

        it = tqdm(people, desc="leave one participant out", unit="fold")
    for p in it:
        test = records.participant == p
        train = records.subset(~test)
        pred["network"][test] = fit(train).predict(features(records.subset(test)))
        const = ConstantArmAngle(float(np.mean(train.alpha)), float(np.std(train.alpha)))
        pred["constant"][test] = const.predict(records.p[test])
    return pred


def _participant_rows(
    residuals: Mapping[str, np.ndarray], records: ArmAngleRecords, n_boot: int, seed: int
) -> dict[str, dict[str, dict[str, float]]]:
    """Per participant and model: rms (deg) with its trial-bootstrap interval, mean residual
    (deg), records and trials."""
    rows: dict[str, dict[str, dict[str, float]]] = {}
    for p in records.participants():
        idx = np.flatnonzero(records.participant == p)
        trials = records.trial[idx]
        rows[p] = {}
        for name, r in residuals.items():
            rp = r[idx]
            value, low, high = cluster_bootstrap(
                lambda i, rp=rp: _rms(rp[i]), trials, n_boot=n_boot, seed=seed
            )
            rows[p][name] = {
                "rms_deg": math.degrees(value),
                "low": math.degrees(low),
                "high": math.degrees(high),
                "bias_deg": math.degrees(float(np.mean(rp))),
                "records": len(idx),
                "trials": len(set(trials.tolist())),
            }
    return rows


def _summary(
    residuals: Mapping[str, np.ndarray], records: ArmAngleRecords, n_boot: int, seed: int
) -> dict[str, dict[str, float]]:
    """Over all held-out records: rms (deg) of each model with the participant-bootstrap
    interval, and the network's paired difference from each baseline."""
    who = records.participant
    out: dict[str, dict[str, float]] = {}
    for name, r in residuals.items():
        value, low, high = cluster_bootstrap(
            lambda i, r=r: _rms(r[i]), who, n_boot=n_boot, seed=seed
        )
        out[name] = {
            "rms_deg": math.degrees(value),
            "low": math.degrees(low),
            "high": math.degrees(high),
        }
    net = residuals["network"]
    for name in (n for n in residuals if n != "network"):
        base = residuals[name]
        value, low, high = cluster_bootstrap(
            lambda i, b=base: _rms(net[i]) - _rms(b[i]), who, n_boot=n_boot, seed=seed
        )
        out[f"network_minus_{name}"] = {
            "rms_deg": math.degrees(value),
            "low": math.degrees(low),
            "high": math.degrees(high),
        }
    return out


def _by_task(residuals: Mapping[str, np.ndarray], records: ArmAngleRecords) -> dict[str, dict]:
    """rms (deg) of each model per task, pooled over the held-out participants, and the sd of
    the arm angle there."""
    out: dict[str, dict] = {}
    for task in sorted(set(records.task.tolist())):
        sel = records.task == task
        out[task] = {name: math.degrees(_rms(r[sel])) for name, r in residuals.items()}
        out[task]["alpha_mean_deg"] = math.degrees(float(np.mean(records.alpha[sel])))
        out[task]["alpha_sd_deg"] = math.degrees(float(np.std(records.alpha[sel])))
        out[task]["records"] = int(sel.sum())
    return out


def cross_validate(
    records: ArmAngleRecords,
    fit: Fit,
    *,
    features: Callable[[ArmAngleRecords], np.ndarray] | None = None,
    kim: ArmAngleModel = CALIBRATED,
    n_boot: int = 2000,
    seed: int = 0,
    progress: bool = False,
) -> dict:
    """Leave-one-participant-out scores of the model ``fit`` trains, against the baselines
    (module docstring). The model predicts from ``features(records)`` (default the
    normalised wrist ``records.p``; another input set is for comparisons).

    Returns a dict: ``participants`` (per participant and model), ``summary``, ``by_task``,
    ``spread`` (rad: spread, between, within of the network's held-out residuals),
    ``scatter_deg`` (between-person sd per model), ``predictions`` (rad, per model: arrays,
    which callers leave out of JSON), ``bootstrap``, ``records`` and ``seconds``.
    """
    t0 = time.perf_counter()
    pred = _held_out(records, fit, features or (lambda r: r.p), progress)
    pred["kim"] = kim_predictions(records, kim)
    residuals = {name: wrap(records.alpha - pred[name]) for name in MODELS}
    spread = spread_of(residuals["network"], records.participant)
    return {
        "participants": _participant_rows(residuals, records, n_boot, seed),
        "summary": _summary(residuals, records, n_boot, seed),
        "by_task": _by_task(residuals, records),
        "spread": {"spread": spread[0], "between": spread[1], "within": spread[2]},
        "scatter_deg": {name: between_person_scatter(r, records) for name, r in residuals.items()},
        "predictions": pred,
        "bootstrap": {"resamples": n_boot, "seed": seed, "level": 0.95},
        "records": len(records),
        "seconds": round(time.perf_counter() - t0, 1),
    }


def paired_comparison(
    base: Mapping, other: Mapping, records: ArmAngleRecords, *, n_boot: int = 2000, seed: int = 0
) -> dict[str, float]:
    """The ``network`` of the cross-validation ``other`` against that of ``base`` on the same
    records: rms (deg) of each, and ``other - base`` with its participant-bootstrap interval.
    Why: settings are compared under the same resamples, not by overlapping intervals."""
    rb = wrap(records.alpha - base["predictions"]["network"])
    ro = wrap(records.alpha - other["predictions"]["network"])
    value, low, high = cluster_bootstrap(
        lambda i: _rms(ro[i]) - _rms(rb[i]), records.participant, n_boot=n_boot, seed=seed
    )
    return {
        "rms_deg": math.degrees(_rms(ro)),
        "base_rms_deg": math.degrees(_rms(rb)),
        "minus_base_deg": math.degrees(value),
        "low": math.degrees(low),
        "high": math.degrees(high),
    }


def kim_calibration_scatter(
    recordings: Sequence[Recording], participants: Mapping[str, Participant]
) -> dict[str, dict]:
    """The between-person sd as the Kim calibration measures it (its ``sd_participant``,
    deg), on the recordings it was made from (:data:`CALIBRATED_ON`, forward and across: the
    figure the stiffness card quotes) and on every participant and task here (in sample: the
    calibration sees them all). Each also gives the residual's sd (deg) and the frames."""
    seated = [
        r for r in recordings if r.participant in CALIBRATED_ON and r.task in ("forward", "across")
    ]
    out = {}
    for key, recs in (("calibrated_on_forward_across", seated), ("all", list(recordings))):
        if not recs:
            continue
        cal = calibrate(recs, participants)
        out[key] = {
            "sd_participant_deg": math.degrees(cal.model.sd_participant),
            "sd_block_deg": math.degrees(cal.model.sd_block),
            "sd_trial_deg": math.degrees(cal.model.sd_trial),
            "sd_within_deg": math.degrees(cal.model.sd_within),
            "residual_sd_deg": cal.calibrated_residual[1],
            "frames": cal.frames,
            "participants": sorted({r.participant for r in recs}),
            "tasks": sorted({r.task for r in recs}),
        }
    return out
