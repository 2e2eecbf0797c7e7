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


def data_card(
    net: NetworkStiffness,
    dataset: StiffnessDataset,
    *,
    date: str,
    commands: list[str],
    paper_scores: dict,
) -> str:
    """Markdown data card: data used, split, scores next to the paper's, how to reproduce."""
    m, dm = net.meta, dataset.meta
    tr = m.get("training", {})
    split = m.get("split", {})
    sc = m.get("scores_held_out_participants", {})
    pp = m.get("scores_paper_protocol")
    counts = dm.get("counts", {})
    real, syn = dm.get("real", {}), dm.get("synthetic", {})
    aam = dm.get("arm_angle_model", {})
    cmp_ = dm.get("arm_angle_comparison_deg", {})
    params = dm.get("arm_parameters", {})
    sd = aam.get("sd_deg", {})
    sd_participant, sd_block = sd.get("participant", 0.0), sd.get("block", 0.0)
    sd_within = sd.get("within_trial", 0.0)
    r = cmp_.get("real")
    real_alpha = f"{r['all_mean']:.1f} +- {r['all_sd']:.1f}" if r else "?"
    lines = [
        f"# Stiffness network for `{dm.get('robot', '?')}`: data card",
        "",
        f"Date: {date}. File: `stiffness.npz` (weights; layout in "
        "`wholebody.arm.network`). Load it with "
        "`wholebody.humanlike.default_stiffness(robot)`.",
        "",
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
        "",
        "## Data",
        "",
        f"- **Real**: {real.get('source', '-')}. Participants "
        f"{', '.join(real.get('participants', []))}; {real.get('trials', 0)} trials. "
        f"Turned 180 deg about z (participant faced -y): {len(real.get('turned_180', []))} "
        "trials (ADL009).",
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
    for key, label in (("real", "real (240 trials)"), ("synthetic_tabletop", "synthetic tabletop"),
                       ("synthetic_standing", "synthetic standing")):  # fmt: skip
        c = cmp_.get(key)
        if c:
            lines.append(
                f"| {label} | {c['start_mean']:.1f} +- {c['start_sd']:.1f} | {c['end_mean']:.1f} "
                f"+- {c['end_sd']:.1f} | {c['all_mean']:.1f} +- {c['all_sd']:.1f} | "
                f"{100 * c['negative_fraction']:.0f} % |"
            )
    lines += [
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
        "",
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
        _row("training mean", sc.get("mean")),
        _row("network, training records", sc.get("network_train")),
        "",
        f"Label sd on the test participants: {np.sqrt(np.var(_test_k(dataset, split))):.4f} "
        "N m/rad. SVR hyper-parameters (grouped 3-fold CV on the training participants): "
        f"{m.get('svr_params', '-')}.",
    ]
    sel = m.get("model_selection")
    if sel:
        lines += [
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
    gn = m.get("gradient_norm")
    if gn:
        lines += [
            "",
            "Smoothness over the training inputs' bounding box (21^3 grid): |dk/dp| median "
            f"{gn['grad_median']:.2f}, 99th percentile {gn['grad_p99']:.2f}, max "
            f"{gn['grad_max']:.2f} N m/rad per m; k from {gn['k_min']:.3f} to {gn['k_max']:.3f} "
            "N m/rad.",
        ]
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
    lines += [
        "",
        "## Reading the scores",
        "",
        "The label is driven by the arm angle (`k ~ A |alpha| / pi` for small alpha), and the "
        "arm angle people choose for a given wrist position varies: in the real reaches it is "
        f"{real_alpha} deg, and its scatter about the fitted arm-angle model has sd "
        f"{sd_participant:.1f} deg between participants, {sd_block:.1f} deg between tasks and "
        f"arms of a participant and {sd_within:.1f} deg within a trial. Wrist position alone "
        "therefore explains little of k across "
        "people, and held-out participants score far below the paper's figures, which come "
        "from a random split of records of the same people. The network is best read as the "
        "population-mean stiffness over the workspace. The paper's MSE is on its own robot's "
        "scale of k, so only R^2 compares across the two.",
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
        (axes[0, 0], "sagittal plane y = 0 (x forward, z up)", "x (m)", "z (m)",
         lambda a, b: np.stack([a, np.zeros_like(a), b], -1), xs, g, (0, 2)),
        (axes[0, 1], "horizontal plane z = -0.25 m (x forward, y medial)", "x (m)", "y (m)",
         lambda a, b: np.stack([a, b, np.full_like(a, -0.25)], -1), xs, g, (0, 1)),
        (axes[1, 0], "horizontal plane z = +0.15 m", "x (m)", "y (m)",
         lambda a, b: np.stack([a, b, np.full_like(a, 0.15)], -1), xs, g, (0, 1)),
    ]  # fmt: skip
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
        ax.set(title=f"held-out participants: {', '.join(test)}", xlabel="label k (N m/rad)",
               ylabel="network k (N m/rad)")  # fmt: skip
    else:
        ax.axis("off")
    fig.suptitle("Stiffness network over the workspace (wrist relative to the shoulder, "
                 "canonical axes; dots: training records)")  # fmt: skip
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path
