"""The data card of a trained stiffness network and a plot of k over the workspace."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wholebody.arm.network import NetworkStiffness
from wholebody.files import save_figure
from wholebody.humanlike.dataset import StiffnessDataset

__all__ = ["data_card", "plot_workspace"]


def _row(name: str, s: dict | None, paper: dict | None = None) -> str:
    if s is None:
        return f"| {name} | - | - | - |"
    p = f"{paper['r2']:.4f} / {paper['mse']:.4f}" if paper else "-"
    return f"| {name} | {s['r2']:.3f} | {s['mse']:.4f} | {p} |"


def _model_lines(m: dict, params: dict) -> list[str]:
    tr = m.get("training", {})
    return [
        "## Model",
        "",
        "- Input: robot wrist relative to the shoulder, canonical arm axes (x forward, y "
        "medial, z up; m). Output: virtual torsion-spring stiffness k (N m/rad).",
        f"- Fully connected, tanh hidden layers {tuple(tr.get('hidden', []))}, input and output "
        "standardised with the training set's mean and sd, smooth floor "
        f"`softplus_beta` (1/beta = 1 % of the label sd) so that k >= 0.",
        f"- Trained with PyTorch {tr.get('torch', '')}: MSE, {tr.get('optimizer', 'Adam')} "
        f"(weight decay {tr.get('weight_decay', 0):g}), lr {tr.get('lr')}, batch "
        f"{tr.get('batch_size')}, {tr.get('epochs')} epochs, seed {tr.get('seed')} "
        f"({tr.get('records')} training records, {tr.get('seconds')} s on "
        f"{tr.get('threads', 1)} CPU thread{'' if tr.get('threads', 1) == 1 else 's'}; "
        f"final training loss {tr.get('final_loss', float('nan')):.3f} of the label variance).",
        "- Labels: `k = A sin|alpha| / (pi - |alpha|)`, `A = g (m1 c1 + m2 (1 - c2)) rho "
        "sin(theta)` with the robot's arm "
        f"(L1 {params.get('upper_arm', 0):.4f} m, L2 {params.get('forearm', 0):.4f} m, m1 "
        f"{params.get('upper_arm_mass', 0)} kg, m2 {params.get('forearm_mass', 0)} kg, c1 "
        f"{params.get('upper_arm_com', 0):.2f}, c2 {params.get('forearm_com', 0):.2f}), after "
        "the paper's posture mapping (directions kept, robot lengths).",
    ]


def _synthetic_lines(dm: dict) -> list[str]:
    """The synthetic participants, their arm-angle model and its comparison with the real
    seated reaches (nothing for a dataset of real recordings only)."""
    syn, aam = dm.get("synthetic"), dm.get("arm_angle_model", {})
    if not syn:
        return [
            "- No synthetic data (`wholebody stiffness dataset --synthetic-participants N` "
            "adds them)."
        ]
    lines = [
        "- "
        + syn.get("note", "SYNTHETIC: -").replace("SYNTHETIC:", "**SYNTHETIC**:", 1)
        + "; participants "
        + ", ".join(
            f"{p['id']} ({p['sex']}, {p['stature_m']:.3f} m)" for p in syn.get("participants", [])
        )
        + f"; {syn.get('trials', 0)} trials, {syn.get('frames', 0)} frames at 30 Hz, "
        f"{syn.get('clamped_targets', 0)} standing targets pulled back into reach.",
        f"- Arm-angle model of the synthetic elbow: {aam.get('criterion', '-')}; target "
        f"{tuple(round(v, 3) for v in aam.get('target_x_stature', []))} x stature (forward, "
        f"medial, up from the shoulder), bias {aam.get('bias_deg', 0):.1f} deg, noise sd "
        + ", ".join(f"{k} {v:.1f}" for k, v in aam.get("sd_deg", {}).items())
        + f" deg, within-trial tau {aam.get('tau_within_s', 0):.2f} s; calibrated on the real "
        f"reaches of {', '.join(aam.get('calibrated_on', [])) or '-'} (no held-out "
        "participant).",
        "",
        "Arm angle (deg), synthetic against real where they overlap (seated tabletop reaches):",
        "",
        "| | start | end of reach | all frames | alpha < 0 |",
        "|---|---|---|---|---|",
    ]
    cmp_ = dm.get("arm_angle_comparison_deg", {})
    for key, label in (
        ("real", "real (forward, across)"),
        ("synthetic_tabletop", "synthetic tabletop"),
        ("synthetic_standing", "synthetic standing"),
    ):
        c = cmp_.get(key)
        if c:
            lines.append(
                f"| {label}, {c['trials']} trials | {c['start_mean']:.1f} +- {c['start_sd']:.1f} "
                f"| {c['end_mean']:.1f} +- {c['end_sd']:.1f} | {c['all_mean']:.1f} +- "
                f"{c['all_sd']:.1f} | {100 * c['negative_fraction']:.0f} % |"
            )
    return lines


def _data_lines(dataset: StiffnessDataset) -> list[str]:
    dm = dataset.meta
    real, counts = dm.get("real", {}), dm.get("counts", {})
    tasks = real.get("tasks") or {}
    per_task = ", ".join(f"{t} {n}" for t, n in tasks.items())
    return [
        "## Data",
        "",
        f"- **Real**: {real.get('source', '-')}. Participants "
        f"{', '.join(real.get('participants', []))}; {real.get('trials', 0)} trials"
        + (f" ({per_task})" if per_task else "")
        + f". Turned 180 deg about z (participant faced -y): {len(real.get('turned_180', []))} "
        "trials (ADL009).",
        *_synthetic_lines(dm),
        "",
        "Frames dropped as ill-conditioned (a frame may trip several rules): "
        + "; ".join(
            f"{src}: {c.get('frames', 0)} frames, straight {c.get('straight', 0)}, vertical "
            f"{c.get('vertical', 0)}, forearm {c.get('forearm', 0)}, kept {c.get('kept', 0)}, "
            f"records {c.get('records', 0)}"
            for src, c in sorted(counts.items())
        )
        + ". Rules: "
        + "; ".join(f"{k}: {v}" for k, v in dm.get("rules", {}).items())
        + f". Records: {len(dataset)} ({dm.get('n_records')} requested, evenly spaced in "
        "time within each trial, every trial weighted alike).",
    ]


def _interval(v: dict) -> str:
    return f"{v['r2']:.3f} [{v['low']:.3f}, {v['high']:.3f}]"


def _per_participant_lines(m: dict) -> list[str]:
    """R^2 per real held-out participant with intervals, every model, and by task."""
    det = m.get("scores_real_held_out") or {}
    per = det.get("per_participant")
    if not per:
        return []
    names = list(per)
    groups = list(next(iter(per.values())))
    label = {"network": "network", "svr": "SVR", "mean": "training mean", "linear": "linear"}
    boot = det.get("bootstrap", {})
    lines = [
        "",
        "On the real held-out participants, each alone (R^2 about the participant's own mean: "
        "how well a new person's k is predicted) and together ('all'), with 95 % bootstrap "
        f"intervals ({boot.get('resamples')} resamples of the trials, seed "
        f"{boot.get('seed')}); every model is measured on the same records in the same way:",
        "",
        "| participant | " + " | ".join(label.get(n, n) for n in names) + " |",
        "|---|" + "---|" * len(names),
    ]
    for g in groups:
        lines.append(f"| {g} | " + " | ".join(_interval(per[n][g]) for n in names) + " |")
    rows = [
        (t, r)
        for key in ("by_task", "by_task_group")
        for t, r in _transpose(det.get(key, {})).items()
        if t != "all"
    ]
    if rows:
        lines += [
            "",
            "By task, and by the seated reaches at table height against the hand raised to the "
            "face (R^2 about the task's mean "
            "over the real held-out participants, same intervals):",
            "",
            "| task | records | " + " | ".join(label.get(n, n) for n in names) + " |",
            "|---|---|" + "---|" * len(names),
            *(
                f"| {t} | {next(iter(r.values()))['n']} | "
                + " | ".join(_interval(r[n]) for n in names)
                + " |"
                for t, r in rows
            ),
        ]
    return lines


def _transpose(table: dict) -> dict:
    """``{model: {group: v}}`` as ``{group: {model: v}}``."""
    out: dict = {}
    for model, groups in table.items():
        for g, v in groups.items():
            out.setdefault(g, {})[model] = v
    return out


def _baseline_lines(m: dict) -> list[str]:
    """The network's R^2 less each baseline's on the same records, paired, and the verdict
    the interval supports."""
    diffs = (m.get("scores_real_held_out") or {}).get("network_minus") or {}
    if not diffs:
        return []
    label = {"linear": "a linear model (least squares)", "svr": "the SVR"}
    lines = [
        "",
        "The network against its baselines, paired (R^2 of the network less the baseline's, "
        "the same records and resamples; an interval above 0: the network predicts better):",
        "",
        "| participant | "
        + " | ".join(f"network - {n.replace('svr', 'SVR')}" for n in diffs)
        + " |",
        "|---|" + "---|" * len(diffs),
    ]
    for g in next(iter(diffs.values())):
        lines.append(f"| {g} | " + " | ".join(_interval(d[g]) for d in diffs.values()) + " |")
    lines.append("")
    for name, d in diffs.items():
        low, high = d["all"]["low"], d["all"]["high"]
        verdict = "better than" if low > 0 else "worse than" if high < 0 else "no better than"
        lines.append(
            f"- Over the held-out participants together the network predicts {verdict} "
            f"{label.get(name, name)}: {_interval(d['all'])}."
        )
    return lines


def _reference_lines(m: dict) -> list[str]:
    refs = m.get("references") or {}
    lines = []
    for name, r in refs.items():
        tr, split = r.get("training") or {}, r.get("split") or {}
        data = ", ".join(
            f"{src} {c.get('records', 0)} records"
            for src, c in sorted((r.get("dataset_counts") or {}).items())
        )
        lines.append(
            f"- {name}: dated {r.get('date')}, trained on {tr.get('records')} records "
            f"({data}; held out {', '.join(split.get('test_participants', []))}), hidden "
            f"{tuple(tr.get('hidden', []))}, weight decay {tr.get('weight_decay', 0):g}."
        )
    if lines:
        lines = [
            "",
            "Reference networks scored above (they held out the same participants):",
            "",
            *lines,
            *_verdicts(m, refs),
        ]
    return lines


def _verdicts(m: dict, refs: dict) -> list[str]:
    """For each reference: the network against it on the real held-out participants."""
    per = (m.get("scores_real_held_out") or {}).get("per_participant", {})
    out = []
    for name in refs:
        if name not in per or "network" not in per:
            continue
        people = [g for g in per["network"] if g != "all"]
        wins = sum(per["network"][g]["r2"] > per[name][g]["r2"] for g in people)
        out.append(
            f"- This network against {name}, same records, same bootstrap: R^2 "
            f"{_interval(per['network']['all'])} against {_interval(per[name]['all'])} over the "
            f"real held-out participants together; higher for {wins} of {len(people)} of them."
        )
    return out


def _selection_lines(m: dict) -> list[str]:
    sel = m.get("model_selection")
    if not sel:
        return []
    return [
        "",
        "Hidden sizes and weight decay chosen by grouped 3-fold cross-validation on the "
        "training participants (one-standard-error rule: the simplest candidate -- largest "
        "weight decay, then fewest parameters -- within one standard error of the best):",
        "",
        "| hidden | weight decay | CV MSE +- SE | CV R^2 | chosen |",
        "|---|---|---|---|---|",
        *(
            f"| {tuple(r['hidden'])} | {r['weight_decay']:g} | {r['cv_mse']:.5f} +- "
            f"{r['cv_mse_se']:.5f} | {r['cv_r2']:.3f} | {'yes' if r.get('chosen') else ''} |"
            for r in sel
        ),
    ]


def _scores_lines(net: NetworkStiffness, dataset: StiffnessDataset, paper_scores: dict) -> list:
    m = net.meta
    split = m.get("split", {})
    sc = m.get("scores_held_out_participants", {})
    refs = [n for n in (m.get("references") or {}) if n in sc]
    lines = [
        "## Split",
        "",
        f"By participant. Held out (never seen in training): "
        f"{', '.join(split.get('test_participants', []))}; {split.get('test_records')} test "
        f"records, {split.get('train_records')} training records.",
        "",
        "## Scores on the held-out participants",
        "",
        "| model | R^2 | MSE ((N m/rad)^2) | paper R^2 / MSE |",
        "|---|---|---|---|",
        _row("network", sc.get("network"), paper_scores.get("network")),
        _row("SVR (RBF)", sc.get("svr"), paper_scores.get("svr")),
        _row("linear (least squares)", sc.get("linear")),
        _row("training mean", sc.get("mean")),
        *(_row(n, sc.get(n)) for n in refs),
        _row("network, training records", sc.get("network_train")),
        "",
        f"Label sd on the test participants: {np.sqrt(np.var(_test_k(dataset, split))):.4f} "
        "N m/rad. SVR hyper-parameters (grouped 3-fold CV on the training participants): "
        f"{m.get('svr_params', '-')}.",
        *_per_participant_lines(m),
        *_baseline_lines(m),
        *_reference_lines(m),
        *_selection_lines(m),
    ]
    gn = m.get("gradient_norm")
    if gn:
        lines += [
            "",
            "Smoothness over the training inputs' bounding box (21^3 grid): |dk/dp| median "
            f"{gn['grad_median']:.2f}, 99th percentile {gn['grad_p99']:.2f}, max "
            f"{gn['grad_max']:.2f} N m/rad per m; k from {gn['k_min']:.3f} to {gn['k_max']:.3f} "
            "N m/rad.",
        ]
    pp = m.get("scores_paper_protocol")
    if pp:
        lines += [
            "",
            "For comparison only, the paper's protocol (300 random records held out, so the "
            "same participants and trials are in both sets):",
            "",
            "| model | R^2 | MSE ((N m/rad)^2) | paper R^2 / MSE |",
            "|---|---|---|---|",
            _row("network", pp.get("network"), paper_scores.get("network")),
            _row("SVR (RBF)", pp.get("svr"), paper_scores.get("svr")),
        ]
    return lines


def _reading_lines(dm: dict, arm_angle_spread: dict | None) -> list[str]:
    sd = dm.get("arm_angle_model", {}).get("sd_deg", {})
    if arm_angle_spread:
        scatter = (
            f"about the arm-angle network of people (`data/arm_angle/README.md`, wrist position "
            f"only, scored on people it never saw) it scatters by {arm_angle_spread['between']:.1f}"
            f" deg between participants and {arm_angle_spread['within']:.1f} deg within one"
        )
    else:
        scatter = (
            f"about Kim et al.'s calibrated model it scatters by "
            f"{sd.get('participant', 0.0):.1f} deg between participants"
        )
    return [
        "## Reading the scores",
        "",
        "The label is driven by the arm angle (`k ~ A |alpha| / pi` for small alpha), and the "
        "arm angle people choose for a given wrist position varies: "
        f"{scatter}. Wrist position therefore explains k only as far as it decides the arm "
        "angle: across tasks that put the wrist in different places (the table, the mouth, "
        "the head) it explains much of it, within one kind of seated reach little (the "
        "by-task table). The network is best read as the population-mean stiffness over the "
        "workspace. The paper's figures come from a random split of records of the same "
        "people (the paper-protocol table, when it is run); its MSE is on its own robot's "
        "scale of k, so only R^2 compares across the two.",
    ]


def data_card(
    net: NetworkStiffness,
    dataset: StiffnessDataset,
    *,
    date: str,
    commands: list[str],
    paper_scores: dict,
    arm_angle_spread: dict | None = None,
) -> str:
    """Markdown data card: data used, split, scores next to the paper's and per real held-out
    participant with intervals, how to reproduce. ``arm_angle_spread`` (deg: ``between``,
    ``within``) quotes the arm-angle network's scatter of people in the reading of the
    scores."""
    dm = dataset.meta
    lines = [
        f"# Stiffness network for `{dm.get('robot', '?')}`: data card",
        "",
        f"Date: {date}. File: `stiffness.npz` (weights; layout in "
        "`wholebody.arm.network`). Load it with "
        "`wholebody.humanlike.default_stiffness(robot)`.",
        "",
        *_model_lines(net.meta, dm.get("arm_parameters", {})),
        "",
        *_data_lines(dataset),
        "",
        *_scores_lines(net, dataset, paper_scores),
        "",
        *_reading_lines(dm, arm_angle_spread),
        "",
        "## Reproduce",
        "",
        "```",
        *commands,
        "```",
        "",
    ]
    return "\n".join(lines)


def _test_k(dataset: StiffnessDataset, split: dict) -> np.ndarray:
    test = split.get("test_participants", [])
    mask = np.isin(dataset.participant, test)
    return dataset.k[mask] if mask.any() else dataset.k


def plot_workspace(
    net: NetworkStiffness,
    path: str | Path,
    dataset: StiffnessDataset | None = None,
    *,
    test_participants: list[str] | None = None,
) -> Path:
    """PNG of k over the workspace: the sagittal plane through the shoulder (y = 0) and
    horizontal planes below and above the shoulder, with the training records' footprint;
    and, given a dataset, predicted against labelled k on the held-out participants."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(2, 2, figsize=(10, 8.5), constrained_layout=True)
    g = np.linspace(-0.5, 0.5, 121)
    xs = np.linspace(-0.1, 0.55, 121)
    panels = [
        (
            axes[0, 0],
            "sagittal plane y = 0 (x forward, z up)",
            "x (m)",
            "z (m)",
            lambda a, b: np.stack([a, np.zeros_like(a), b], -1),
            xs,
            g,
            (0, 2),
        ),
        (
            axes[0, 1],
            "horizontal plane z = -0.25 m (x forward, y medial)",
            "x (m)",
            "y (m)",
            lambda a, b: np.stack([a, b, np.full_like(a, -0.25)], -1),
            xs,
            g,
            (0, 1),
        ),
        (
            axes[1, 0],
            "horizontal plane z = +0.15 m",
            "x (m)",
            "y (m)",
            lambda a, b: np.stack([a, b, np.full_like(a, 0.15)], -1),
            xs,
            g,
            (0, 1),
        ),
    ]
    vmax = None
    for ax, title, xl, yl, make, a, b, (i, j) in panels:
        A, B = np.meshgrid(a, b)
        K = net.predict(make(A, B))
        vmax = vmax or float(np.percentile(K, 99))
        im = ax.pcolormesh(A, B, K, shading="auto", cmap="viridis", vmin=0, vmax=vmax)
        if dataset is not None:
            ax.scatter(dataset.wrist[:, i], dataset.wrist[:, j], s=1, c="w", alpha=0.15)
        ax.set(title=title, xlabel=xl, ylabel=yl, aspect="equal")
        fig.colorbar(im, ax=ax, label="k (N m/rad)")
    ax = axes[1, 1]
    if dataset is not None:
        test = test_participants or net.meta.get("split", {}).get("test_participants", [])
        mask = np.isin(dataset.participant, test)
        if mask.any():
            y, yp = dataset.k[mask], net.predict(dataset.wrist[mask])
            for src, col in (("real", "tab:blue"), ("synthetic", "tab:orange")):
                s = dataset.source[mask] == src
                ax.scatter(y[s], yp[s], s=3, alpha=0.4, c=col, label=src)
            top = float(max(y.max(), yp.max()))
            ax.plot([0, top], [0, top], "k--", lw=1)
            ax.legend(loc="upper left")
        ax.set(
            title=f"held-out participants: {', '.join(test)}",
            xlabel="label k (N m/rad)",
            ylabel="network k (N m/rad)",
        )
    else:
        ax.axis("off")
    fig.suptitle(
        "Stiffness network over the workspace (wrist relative to the shoulder, "
        "canonical axes; dots: training records)"
    )
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path
