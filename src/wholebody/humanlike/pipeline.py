"""End to end: recordings -> dataset, and dataset -> trained, evaluated models.

:func:`make_dataset` gathers the real recordings (and, as an option, synthetic ones),
labels them for a robot and writes the dataset; :func:`fit_and_evaluate` splits the dataset
by participant, trains the network and the SVR baseline on the training participants and
scores both (and a mean predictor, and any reference network such as the one shipped
before) on the held-out participants: pooled, and per real participant with bootstrap
intervals. Optionally it also scores the paper's own protocol (300 random records held out,
participants shared), for comparison only.
Torch and scikit-learn are imported only when a model is fitted.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from wholebody.arm.network import NetworkStiffness
from wholebody.errors import DataError
from wholebody.humanlike.arm_angle_model import (
    CALIBRATED,
    CALIBRATED_ON,
    ArmAngleModel,
    Calibration,
    calibrate,
    summarise_arm_angles,
)
from wholebody.humanlike.dataset import (
    DEFAULT_TEST_PARTICIPANTS,
    BuildReport,
    StiffnessDataset,
    build_dataset,
)
from wholebody.humanlike.evaluation import (
    paired_r2_difference,
    r2_with_intervals,
    regression_scores,
)
from wholebody.humanlike.linear import fit_linear
from wholebody.humanlike.mapping import ArmParameters
from wholebody.humanlike.recordings import (
    Recording,
    load_participants,
    load_recordings,
    save_npz_recording,
)
from wholebody.humanlike.synthetic import (
    SyntheticSummary,
    VirtualParticipant,
    generate_synthetic,
)

__all__ = [
    "PAPER_SCORES",
    "TASK_GROUPS",
    "FitOutcome",
    "fit_and_evaluate",
    "gradient_norms",
    "group_folds",
    "held_out_details",
    "make_dataset",
    "select_model",
]

BASELINES = ("linear", "svr")
"""The models the network is compared with, paired, on the held-out participants."""
PAPER_SCORES = {"network": {"r2": 0.9304, "mse": 0.1673}, "svr": {"r2": 0.9169, "mse": 0.2352}}


def make_dataset(
    params: ArmParameters,
    *,
    recordings_dir: str | Path | None = None,
    real: bool = True,
    tasks: Sequence[str] | None = None,
    synthetic: Sequence[VirtualParticipant] = (),
    seed: int = 0,
    n_records: int = 5000,
    recalibrate: bool = False,
    held_out: Sequence[str] = DEFAULT_TEST_PARTICIPANTS,
    progress: bool = False,
    synthetic_out: str | Path | None = None,
) -> tuple[StiffnessDataset, BuildReport, dict]:
    """Build the dataset of recorded (and optionally synthetic) arm motions for one robot
    arm.

    ``tasks`` selects the real recordings' tasks (default: all, the bundled data's four:
    seated forward and across reaches, drinking, combing). ``synthetic``: virtual
    participants (for example :data:`~wholebody.humanlike.synthetic.DEFAULT_PARTICIPANTS`)
    whose synthetic reaches are added; none by default. The synthetic recordings it labels
    are also written to ``synthetic_out`` (a directory, ``.npz``) if given.

    The synthetic elbows come from an arm-angle model calibrated on real reaches: the shipped
    :data:`~wholebody.humanlike.arm_angle_model.CALIBRATED`, or with ``recalibrate`` a new fit
    on the real recordings of every participant not in ``held_out``. The participants it was
    calibrated on are stored in the metadata (``arm_angle_model.calibrated_on``), and
    :func:`fit_and_evaluate` refuses to score on any of them: they shaped the training data.

    Returns the dataset, the frame counts and a dict of provenance (calibration, arm-angle
    comparison of the synthetic tabletop block with the real reaches) that is also stored
    in the dataset's metadata.
    """
    recs: list[Recording] = []
    info: dict = {"seed": seed}
    real_recs: list[Recording] = []
    if real:
        real_recs = load_recordings(recordings_dir, progress=progress, tasks=tasks)
        recs += real_recs
        turned = [r.name for r in real_recs if "turned 180" in r.note]
        kinds = sorted({r.task for r in real_recs})
        info["real"] = {
            "source": "UE_ADLdatabase (M. Huang, SFSU, 2021; MIT), subset in "
            f"data/human_reaching: seated participants, tasks {', '.join(kinds)}, both arms, "
            "100 Hz",
            "participants": sorted({r.participant for r in real_recs}),
            "trials": len(real_recs),
            "tasks": {t: sum(r.task == t for r in real_recs) for t in kinds},
            "turned_180": turned,
        }
    model: ArmAngleModel = CALIBRATED
    calibrated_on: list[str] = list(CALIBRATED_ON)
    if recalibrate:
        if not real_recs:
            real_recs = load_recordings(recordings_dir, progress=progress, tasks=tasks)
        used = [r for r in real_recs if r.participant not in set(held_out)]
        if not used:
            raise DataError("recalibrate: every real participant is held out")
        cal: Calibration = calibrate(used, load_participants())
        model = cal.model
        calibrated_on = sorted({r.participant for r in used})
        info["calibration"] = cal.summary()
    if synthetic:
        recs += _synthetic(info, synthetic, seed, model, calibrated_on, real_recs, synthetic_out)
    ds, report = build_dataset(recs, params, n_records=n_records, progress=progress, meta=info)
    return ds, report, info


def _synthetic(
    info: dict,
    synthetic: Sequence[VirtualParticipant],
    seed: int,
    model: ArmAngleModel,
    calibrated_on: list[str],
    real_recs: Sequence[Recording],
    synthetic_out: str | Path | None,
) -> list[Recording]:
    """The synthetic recordings of :func:`make_dataset`, their provenance added to ``info``
    (the arm-angle model, the generator's counts, and the arm angles of the synthetic
    tabletop block next to the real seated reaches)."""
    info["arm_angle_model"] = {
        "calibrated_on": calibrated_on,
        "criterion": "Kim et al. 2012 (IEEE TBME 59(6):1770): maximise the projection of the "
        "wrist manipulability ellipsoid's major axis on the wrist-to-head-target vector",
        "target_x_stature": list(model.target),
        "bias_deg": float(np.degrees(model.bias)),
        "sd_deg": {
            "participant": float(np.degrees(model.sd_participant)),
            "block": float(np.degrees(model.sd_block)),
            "trial": float(np.degrees(model.sd_trial)),
            "within_trial": float(np.degrees(model.sd_within)),
        },
        "tau_within_s": model.tau_within,
    }
    summary = SyntheticSummary()
    syn = generate_synthetic(synthetic, seed=seed, model=model, summary=summary)
    if synthetic_out is not None:
        for rec in syn:
            save_npz_recording(rec, Path(synthetic_out) / f"{rec.name}.npz")
    info["synthetic"] = {
        "participants": [{"id": p.id, "sex": p.sex, "stature_m": p.stature} for p in synthetic],
        "trials": summary.trials,
        "frames": summary.frames,
        "clamped_targets": summary.clamped_targets,
        "note": "SYNTHETIC: paper's protocol (27 standing + 9 tabletop targets), "
        "minimum-jerk wrist paths, elbow from the calibrated arm-angle model",
    }
    comparison = {
        f"synthetic_{task}": summarise_arm_angles([r for r in syn if r.task == task])
        for task in ("tabletop", "standing")
    }
    seated = [r for r in real_recs if r.task in ("forward", "across")]
    if seated:
        comparison["real"] = summarise_arm_angles(seated)
    info["arm_angle_comparison_deg"] = comparison
    return syn


def gradient_norms(net: NetworkStiffness, n: int = 21) -> dict[str, float]:
    """|dk/dp| (N m/rad per m) on an n^3 grid over the training inputs' bounding box: median,
    99th percentile and maximum, and the same for k (N m/rad)."""
    lo, hi = net.input_low, net.input_high
    if lo is None or hi is None or not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        return {}
    axes = [np.linspace(a, b, n) for a, b in zip(lo, hi, strict=True)]
    P = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    g = np.linalg.norm(net.gradient(P), axis=1)
    k = net.predict(P)
    return {
        "grad_median": float(np.median(g)),
        "grad_p99": float(np.percentile(g, 99)),
        "grad_max": float(g.max()),
        "k_min": float(k.min()),
        "k_max": float(k.max()),
    }


def group_folds(groups: np.ndarray, n_splits: int = 3) -> list[tuple[np.ndarray, np.ndarray]]:
    """(train, validation) index pairs holding out whole groups: the sorted group names are
    dealt round-robin into ``n_splits`` folds."""
    names = sorted(set(np.asarray(groups).tolist()))
    n = min(n_splits, len(names))
    if n < 2:
        raise DataError(f"group_folds: need >= 2 groups, got {len(names)}")
    folds = []
    for i in range(n):
        val = np.isin(groups, names[i::n])
        folds.append((np.flatnonzero(~val), np.flatnonzero(val)))
    return folds


def _n_parameters(hidden: Sequence[int]) -> int:
    sizes = [3, *hidden, 1]
    return sum((a + 1) * b for a, b in itertools.pairwise(sizes))


def select_model(
    train: StiffnessDataset,
    candidates: Sequence[dict],
    config: object,
    *,
    n_splits: int = 3,
    progress: bool = False,
) -> tuple[dict, list[dict]]:
    """Choose training settings by grouped cross-validation on the training participants.

    Each candidate (a dict of :class:`~wholebody.humanlike.training.TrainingConfig` fields,
    e.g. ``{"hidden": (16,), "weight_decay": 1e-3}``) is trained on every fold of
    :func:`group_folds` and scored by its mean validation MSE and that mean's standard error
    over the folds. One-standard-error rule: among the candidates whose mean is within one
    standard error of the best mean, the simplest wins: largest weight decay, then fewest
    parameters (smoother k, smaller gradient spikes for the controller).
    """
    from wholebody.humanlike.training import train_network

    folds = group_folds(train.participant, n_splits)
    table = []
    for cand in candidates:
        cfg = replace(config, **cand)  # type: ignore[type-var]
        mses, r2s = [], []
        for tr, va in folds:
            res = train_network(train.wrist[tr], train.k[tr], cfg, progress=progress)
            s = regression_scores(train.k[va], res.network.predict(train.wrist[va]))
            mses.append(s["mse"])
            r2s.append(s["r2"])
        table.append(
            {
                "hidden": list(cfg.hidden),  # type: ignore[attr-defined]
                "weight_decay": float(cfg.weight_decay),  # type: ignore[attr-defined]
                "cv_mse": float(np.mean(mses)),
                "cv_mse_se": float(np.std(mses, ddof=1) / np.sqrt(len(mses))),
                "cv_r2": float(np.mean(r2s)),
            }
        )
    best = min(table, key=lambda r: r["cv_mse"])
    ok = [r for r in table if r["cv_mse"] <= best["cv_mse"] + best["cv_mse_se"]]
    pick = min(ok, key=lambda r: (-r["weight_decay"], _n_parameters(r["hidden"]), r["cv_mse"]))
    for r in table:
        r["chosen"] = r is pick
    return {"hidden": tuple(pick["hidden"]), "weight_decay": pick["weight_decay"]}, table


def _check_reference(name: str, ref: NetworkStiffness, test: Sequence[str]) -> None:
    """A reference network must not have trained on a test participant."""
    held = ref.meta.get("split", {}).get("test_participants")
    if held is None:
        raise DataError(
            f"reference network {name!r}: its file does not say which participants "
            "it held out, so it may have trained on the test participants"
        )
    seen = sorted(set(test) - set(held))
    if seen:
        raise DataError(
            f"reference network {name!r} trained on test participant(s) "
            f"{', '.join(seen)}: they cannot score it"
        )


def _provenance(ref: NetworkStiffness) -> dict:
    """What the card says of a reference network: date, data, split, training settings."""
    keys = ("date", "dataset", "dataset_counts", "split", "training")
    return {k: ref.meta.get(k) for k in keys}


TASK_GROUPS = {"forward+across": ("forward", "across"), "drinking+combing": ("drinking", "combing")}
"""Tasks scored together too: the seated reaches at table height and the tasks that raise the
hand to the face."""


def held_out_details(
    test: StiffnessDataset,
    predictions: Mapping[str, np.ndarray],
    *,
    n_boot: int = 2000,
    seed: int = 0,
) -> dict:
    """Scores of ``predictions`` (name: k per test record) on the **real** test records, from
    :func:`~wholebody.humanlike.evaluation.r2_with_intervals` (R^2 with trial-bootstrap
    intervals, per model): ``per_participant`` (each about its own mean, and ``all``
    pooled), ``by_task`` (per task, from the trial ids, and ``all``) and ``by_task_group``
    (the :data:`TASK_GROUPS` present), and ``network_minus``: per baseline (:data:`BASELINES`)
    the network's R^2 less the baseline's, per participant and ``all``, with its interval over
    the same resamples (paired). Empty without two real records. Why real only: synthetic
    test participants measure the generator, not people."""
    real = test.source == "real"
    if real.sum() < 2:
        return {}
    sub = test.subset(real)
    preds = {name: np.asarray(p)[real] for name, p in predictions.items()}
    tasks = np.array([t.split("_")[1] for t in sub.trial])
    groups = np.full(len(tasks), "", dtype=object)
    for name, members in TASK_GROUPS.items():
        groups[np.isin(tasks, members)] = name
    out = {"bootstrap": {"resamples": n_boot, "seed": seed, "level": 0.95}}
    if "network" in preds:
        out["network_minus"] = {
            name: paired_r2_difference(
                sub.k, preds["network"], p, sub.participant, sub.trial, n_boot=n_boot, seed=seed
            )
            for name, p in preds.items()
            if name in BASELINES
        }
    for key, labels in (
        ("per_participant", sub.participant),
        ("by_task", tasks),
        ("by_task_group", groups),
    ):
        keep = labels != ""  # records of no task group
        if keep.sum() < 2:
            continue
        kept = {name: p[keep] for name, p in preds.items()}
        out[key] = r2_with_intervals(
            sub.k[keep], kept, labels[keep].astype(str), sub.trial[keep], n_boot=n_boot, seed=seed
        )
    return out


@dataclass
class FitOutcome:
    """Trained network, held-out scores and what was held out."""

    network: NetworkStiffness
    scores: dict[str, dict[str, float]]
    test_participants: list[str]
    train_participants: list[str]
    svr_params: dict | None = None
    paper_protocol: dict[str, dict[str, float]] | None = None
    loss: list[float] = field(default_factory=list)
    seconds: float = 0.0


def fit_and_evaluate(
    dataset: StiffnessDataset,
    *,
    test_participants: Sequence[str] = DEFAULT_TEST_PARTICIPANTS,
    config: object | None = None,
    svr: bool = True,
    svr_grid: dict | None = None,
    paper_protocol: bool = False,
    candidates: Sequence[dict] | None = None,
    references: Mapping[str, NetworkStiffness] | None = None,
    n_boot: int = 2000,
    progress: bool = False,
) -> FitOutcome:
    """Split by participant, train the network (``config``: a
    :class:`~wholebody.humanlike.training.TrainingConfig`) and the SVR on the training
    participants, and score both and the training mean on the held-out participants: pooled
    over every held-out record (``scores``), and on the real held-out participants, each
    alone and together, with 95 % bootstrap intervals over their trials
    (:func:`held_out_details`: ``meta["scores_real_held_out"]``).

    ``references`` (name: network, e.g. the network shipped before) are scored on the same
    records in the same way; each must have held out every test participant (its
    ``meta["split"]``), else :class:`DataError`.

    With ``candidates`` the training settings are first chosen by :func:`select_model` on
    the training participants. With ``paper_protocol`` the two models are also trained and
    scored on the paper's split (300 random records held out); those numbers go in
    ``paper_protocol``, for comparison.
    """
    from wholebody.humanlike.training import TrainingConfig, train_network

    config = config or TrainingConfig()
    shaped = set(dataset.meta.get("arm_angle_model", {}).get("calibrated_on", ()))
    leaked = sorted(shaped & set(test_participants))
    if leaked and dataset.meta.get("synthetic"):
        raise DataError(
            f"test participant(s) {', '.join(leaked)} shaped the synthetic training data (the "
            "arm-angle model was calibrated on them): hold out others, or rebuild the dataset "
            "with `wholebody stiffness dataset --calibrate --held-out ...`"
        )
    train, test = dataset.split(test_participants)
    for name, ref in (references or {}).items():
        _check_reference(name, ref, test_participants)
    selection = None
    if candidates:
        chosen, selection = select_model(train, candidates, config, progress=progress)
        config = replace(config, **chosen)  # type: ignore[type-var]
    meta = {
        "robot": dataset.meta.get("robot", ""),
        "split": {
            "test_participants": sorted(set(test_participants)),
            "train_records": len(train),
            "test_records": len(test),
        },
    }
    result = train_network(train.wrist, train.k, config, progress=progress, meta=meta)  # type: ignore[arg-type]
    net = result.network
    net.meta["gradient_norm"] = gradient_norms(net)
    predictions = {
        "network": net.predict(test.wrist),
        "mean": np.full(len(test), train.k.mean()),
        "linear": fit_linear(train.wrist, train.k).predict(test.wrist),
    }
    scores = {
        "network": regression_scores(test.k, predictions["network"]),
        "mean": regression_scores(test.k, predictions["mean"]),
        "linear": regression_scores(test.k, predictions["linear"]),
        "network_train": regression_scores(train.k, net.predict(train.wrist)),
    }
    svr_params = None
    if svr:
        from wholebody.humanlike.svr import fit_svr, select_svr

        svr_params, _ = select_svr(
            train.wrist, train.k, train.participant, grid=svr_grid, progress=progress
        )
        model = fit_svr(train.wrist, train.k, **svr_params)
        scores["svr"] = regression_scores(test.k, model.predict(test.wrist))
        predictions["svr"] = model.predict(test.wrist)
    for name, ref in (references or {}).items():
        predictions[name] = ref.predict(test.wrist)
        scores[name] = regression_scores(test.k, predictions[name])
    paper = None
    if paper_protocol:
        rng = np.random.default_rng(config.seed)  # type: ignore[attr-defined]
        idx = rng.permutation(len(dataset))
        te, tr = idx[:300], idx[300:]
        r2 = train_network(dataset.wrist[tr], dataset.k[tr], config, progress=progress)  # type: ignore[arg-type]
        paper = {"network": regression_scores(dataset.k[te], r2.network.predict(dataset.wrist[te]))}
        if svr:
            m2 = fit_svr(dataset.wrist[tr], dataset.k[tr], **(svr_params or {}))
            paper["svr"] = regression_scores(dataset.k[te], m2.predict(dataset.wrist[te]))
    net.meta["scores_held_out_participants"] = scores
    net.meta["scores_real_held_out"] = held_out_details(
        test, predictions, n_boot=n_boot, seed=config.seed
    )  # type: ignore[attr-defined]
    if references:
        net.meta["references"] = {name: _provenance(ref) for name, ref in references.items()}
    if selection is not None:
        net.meta["model_selection"] = selection
    if svr_params is not None:
        net.meta["svr_params"] = svr_params
    if paper is not None:
        net.meta["scores_paper_protocol"] = paper
    return FitOutcome(
        net,
        scores,
        sorted(set(test.participant.tolist())),
        sorted(set(train.participant.tolist())),
        svr_params,
        paper,
        result.loss,
        result.seconds,
    )
