"""The data card of the human arm-angle network (markdown, numpy only)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

from wholebody.arm.human_arm_angle import NetworkArmAngle
from wholebody.humanlike.arm_angle_data import ArmAngleRecords

__all__ = ["arm_angle_card"]

_LABELS = {
    "network": "network",
    "constant": "constant (training mean)",
    "kim": "Kim et al., CALIBRATED",
}


def _ci(row: Mapping[str, float]) -> str:
    return f"{row['rms_deg']:.1f} [{row['low']:.1f}, {row['high']:.1f}]"


def _model_lines(net: NetworkArmAngle, records: ArmAngleRecords) -> list[str]:
    tr = net.meta.get("training", {})
    lo, hi = net.input_low, net.input_high
    box = "-"
    if lo is not None and hi is not None:
        box = ", ".join(f"{a} {x:+.2f} to {y:+.2f}" for a, x, y in zip("xyz", lo, hi, strict=True))
    deg = math.degrees
    return [
        "## Model",
        "",
        "- Input: the normalised wrist `p = (W - S) / (L1 + L2)`, the wrist relative to the "
        "shoulder in the arm's canonical axes (x forward, y medial, z up; left arms mirrored) "
        "over the arm's length (upper arm + forearm, the trial's median recorded lengths); "
        "dimensionless, so a robot queries it with its own `W - S`, `L1`, `L2` "
        "(`wholebody.arm.normalised_wrist`). Output: the arm angle people hold, `alpha_h` "
        "(rad; `wholebody.arm.angle`: 0 elbow lowest, > 0 outwards, mirrored arms equal), and "
        "its analytic gradient `d alpha_h / dp`.",
        f"- Fully connected, tanh hidden layers {tuple(tr.get('hidden', []))}, linear output; "
        "input and output standardised with the training records' mean and sd. Inputs seen "
        f"(the box `in_range` checks): {box}; outside it the tanh units saturate and "
        "`alpha_h` levels off.",
        f"- Trained with PyTorch {tr.get('torch', '')} in float64: MSE, AdamW (weight decay "
        f"{tr.get('weight_decay', 0):g}), lr {tr.get('lr')}, batch {tr.get('batch_size')}, "
        f"{tr.get('epochs')} epochs, seed {tr.get('seed')} ({tr.get('records')} records of "
        f"all 12 participants, {tr.get('seconds')} s on {tr.get('threads', 1)} CPU "
        f"thread{'' if tr.get('threads', 1) == 1 else 's'}; final training loss "
        f"{tr.get('final_loss', float('nan')):.3f} of the label variance).",
        f"- `spread` {deg(net.spread):.1f} deg (between persons {deg(net.spread_between):.1f}, "
        f"within {deg(net.spread_within):.1f}): the rms of the held-out residuals below, "
        "`spread^2 = between^2 + within^2` with between the rms of each held-out person's "
        "mean residual and within the rms about it. A controller pulling the elbow "
        "towards `alpha_h` is pulling towards a typical person, not a precise one.",
    ]


def _data_lines(records: ArmAngleRecords) -> list[str]:
    c = records.counts
    lines = [
        "## Data",
        "",
        "Real recordings only: UE_ADLdatabase (M. Huang, SFSU, 2021; MIT), subset in "
        "`data/human_reaching` (its README): 12 seated participants "
        f"({', '.join(records.participants())}), both arms, 5 trials per arm and task, 100 Hz. "
        "Frames are dropped where the arm angle is ill-defined or the markers slipped, by the "
        "stiffness labels' rules applied to the person's posture (straight: elbow < 4 cm "
        "from the shoulder-wrist line; vertical: that line < 20 deg from the vertical; "
        "forearm: length > 2 cm from the trial's median), then every trial gives as many "
        "records, evenly spaced in time.",
        "",
        "| task | trials | frames | straight | vertical | forearm | kept | records | "
        "alpha mean +- sd (deg) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for task, n in sorted(c.items()):
        sel = records.task == task
        a = records.alpha[sel]
        lines.append(
            f"| {task} | {n.get('trials', 0)} | {n.get('frames', 0)} | {n.get('straight', 0)} | "
            f"{n.get('vertical', 0)} | {n.get('forearm', 0)} | {n.get('kept', 0)} | "
            f"{n.get('records', 0)} | {math.degrees(a.mean()):.1f} +- "
            f"{math.degrees(a.std()):.1f} |"
        )
    return lines


def _scores_lines(cv: Mapping) -> list[str]:
    boot = cv["bootstrap"]
    lines = [
        "## Scores: leave one participant out",
        "",
        "Each participant's records are predicted by a network trained on the other eleven "
        "(same settings and seed) and by the baselines: the constant (the eleven's mean arm "
        "angle) and Kim et al.'s criterion with the calibration the synthetic stiffness data "
        "use (`wholebody.humanlike.arm_angle_model.CALIBRATED`, from each person's wrist, "
        "lengths and stature; not refitted: it was calibrated on the forward/across reaches "
        "of ADL001, 002, 004-007, 009, 010, 012, which favours it there). rms of "
        "`wrap(alpha - alpha_h)` in deg with 95 % bootstrap intervals "
        f"({boot['resamples']} resamples of the participant's trials, seed {boot['seed']}); "
        "bias: the mean residual.",
        "",
        "| participant | network | constant | Kim (CALIBRATED) | network bias |",
        "|---|---|---|---|---|",
    ]
    for p, row in cv["participants"].items():
        lines.append(
            f"| {p} | {_ci(row['network'])} | {_ci(row['constant'])} | "
            f"{_ci(row['kim'])} | {row['network']['bias_deg']:+.1f} |"
        )
    s = cv["summary"]
    rows = cv["participants"].values()
    wins = {
        b: sum(r["network"]["rms_deg"] < r[b]["rms_deg"] for r in rows) for b in ("constant", "kim")
    }
    lines += [
        f"| all (participants resampled) | {_ci(s['network'])} | {_ci(s['constant'])} | "
        f"{_ci(s['kim'])} | |",
        "",
        f"Paired, under the same participant resamples: network - constant "
        f"{_ci(s['network_minus_constant'])} deg, network - Kim {_ci(s['network_minus_kim'])} "
        f"deg. The network is better for {wins['constant']} of {len(rows)} participants "
        f"against the constant and {wins['kim']} of {len(rows)} against Kim.",
        "",
        "By task (rms, deg, all held-out records of the task):",
        "",
        "| task | network | constant | Kim (CALIBRATED) | alpha mean +- sd |",
        "|---|---|---|---|---|",
    ]
    for task, t in cv["by_task"].items():
        lines.append(
            f"| {task} | {t['network']:.1f} | {t['constant']:.1f} | {t['kim']:.1f} | "
            f"{t['alpha_mean_deg']:.1f} +- {t['alpha_sd_deg']:.1f} |"
        )
    return lines


def _comparison_lines(comparisons: Mapping[str, Mapping]) -> list[str]:
    if not comparisons:
        return []
    better = [name for name, c in comparisons.items() if c["high"] < 0]
    verdict = (
        f"better beyond its interval: {', '.join(better)}"
        if better
        else "none is better beyond its interval"
    )
    lines = [
        "",
        "Other settings under the same cross-validation (for information, not a selection: "
        f"the shipped settings are the defaults; {verdict}): rms over all held-out records "
        "and the paired difference from the shipped settings (deg, participants resampled).",
        "",
        "| variant | rms | minus shipped |",
        "|---|---|---|",
    ]
    for name, c in comparisons.items():
        lines.append(
            f"| {name} | {c['rms_deg']:.1f} | {c['minus_base_deg']:+.2f} "
            f"[{c['low']:+.2f}, {c['high']:+.2f}] |"
        )
    return lines


def _scatter_lines(cv: Mapping, kim_scatter: Mapping[str, Mapping]) -> list[str]:
    sc = cv["scatter_deg"]
    lines = [
        "",
        "## Between-person scatter of the arm angle",
        "",
        "Computed as the Kim calibration computes its `sd_participant` "
        "(`wholebody.humanlike.arm_angle_model.calibrate`): per participant, the mean over "
        "its trials of each trial's mean residual; then the standard deviation of those "
        "12 means (ddof 0; ddof 1 in brackets); 'corrected' removes the sampling noise of "
        "each mean (variance of the means minus the mean squared standard error).",
        "",
        "| residual about | sd (ddof 1) | corrected |",
        "|---|---|---|",
    ]
    for name in ("network", "constant", "kim"):
        r = sc[name]
        what = {
            "network": "the network (held out)",
            "constant": "the constant (held out)",
            "kim": "Kim et al., CALIBRATED",
        }[name]
        lines.append(f"| {what} | {r['sd']:.1f} ({r['sd_ddof1']:.1f}) | {r['sd_corrected']:.1f} |")
    for key, k in kim_scatter.items():
        what = (
            "Kim refitted on ADL001, 002, 004-007, 009, 010, 012, forward/across (how "
            "CALIBRATED was made: the 5.6 deg the stiffness card quotes)"
            if key == "calibrated_on_forward_across"
            else "Kim refitted on all 12 participants and 4 tasks (in sample)"
        )
        lines.append(
            f"| {what}; residual sd {k['residual_sd_deg']:.1f}, {k['frames']} frames "
            f"| {k['sd_participant_deg']:.1f} | - |"
        )
    lines += [
        "",
        "So people differ from one another by about "
        f"{sc['network']['sd']:.1f} deg in the arm angle they hold for the same normalised "
        "wrist (the network's between-person part of its spread), against a within-person "
        "scatter about "
        f"{math.degrees(cv['spread']['within']):.1f} deg.",
    ]
    return lines


def arm_angle_card(
    net: NetworkArmAngle,
    records: ArmAngleRecords,
    cv: Mapping,
    *,
    date: str,
    commands: Sequence[str],
    comparisons: Mapping[str, Mapping] | None = None,
    kim_scatter: Mapping[str, Mapping] | None = None,
) -> str:
    """Markdown data card: model, data, cross-validated scores against the baselines, the
    between-person scatter, other settings, how to reproduce."""
    lines = [
        "# Human arm-angle network: data card",
        "",
        f"Date: {date}. File: `human_arm_angle.npz` (layout in "
        "`wholebody.arm.human_arm_angle`). Load it with "
        "`wholebody.arm.default_arm_angle_model()`; `evaluate(p)` returns `alpha_h` (rad) and "
        "`d alpha_h / dp`.",
        "",
        *_model_lines(net, records),
        "",
        *_data_lines(records),
        "",
        *_scores_lines(cv),
        *_comparison_lines(comparisons or {}),
        *_scatter_lines(cv, kim_scatter or {}),
        "",
        "## Limits",
        "",
        "- Seated people: the wrist goes from the table (forward, across) to the mouth "
        "(drinking) and over the head (combing), close to the body; a robot reaching a "
        "shelf far forward at shoulder height asks for `p` the recordings cover thinly or "
        "not at all (check `in_range`), where `alpha_h` is an extrapolation.",
        "- The 'shoulder' is the greater tubercle (a proxy lateral of the joint centre; "
        "`data/human_reaching/README.md`), which shifts every arm angle a little.",
        "",
        "## Reproduce",
        "",
        "```",
        *commands,
        "```",
        "",
    ]
    return "\n".join(lines)
