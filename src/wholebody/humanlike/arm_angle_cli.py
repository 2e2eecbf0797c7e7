"""``wholebody stiffness armangle score | fit``: the human arm-angle model from the shell.

::

    wholebody stiffness armangle score                  # leave-one-participant-out table
    wholebody stiffness armangle fit --out data/arm_angle/human_arm_angle.npz \\
        --card data/arm_angle/README.md                 # the same, then the shipped network

``score`` trains one network per held-out participant and prints (and with ``--out`` writes
as JSON) the per-participant rms against the baselines; ``fit`` does the same (its spread
and its card need it), may score other settings for comparison, then trains the network on
every participant and writes it with its data card. Wired in by
:func:`wholebody.humanlike.cli.add_stiffness_parser`.
"""

from __future__ import annotations

import argparse
import datetime
import math
from pathlib import Path
from shlex import quote

import numpy as np

from wholebody.files import write_json, write_text
from wholebody.humanlike.cli import int_at_least, int_list, name_list

__all__ = ["add_arm_angle_parser"]


def _config(args: argparse.Namespace, **change: object):
    from wholebody.humanlike.arm_angle_fit import ArmAngleConfig

    values = dict(
        hidden=tuple(args.hidden),
        epochs=args.epochs,
        lr=args.lr,
        batch_size=args.batch_size,
        weight_decay=args.weight_decay,
        seed=args.seed,
    )
    return ArmAngleConfig(**{**values, **change})  # type: ignore[arg-type]


def _records(args: argparse.Namespace):
    """The recordings (all four tasks unless ``--tasks``) and their arm-angle records."""
    from wholebody.humanlike.arm_angle_data import arm_angle_records
    from wholebody.humanlike.recordings import load_participants, load_recordings

    recs = load_recordings(args.recordings, tasks=args.tasks, progress=not args.quiet)
    return recs, arm_angle_records(recs, load_participants(), n_records=args.records)


def _cross_validate(args: argparse.Namespace, records, config, *, hand: bool = False) -> dict:
    from wholebody.humanlike.arm_angle_fit import train_arm_angle, train_predictor
    from wholebody.humanlike.arm_angle_scores import cross_validate

    if hand:  # the hand direction as three more inputs: torch models, not exported
        return cross_validate(
            records,
            lambda tr: train_predictor(np.hstack([tr.p, tr.hand]), tr.alpha, config),
            features=lambda r: np.hstack([r.p, r.hand]),
            n_boot=args.bootstrap,
            seed=args.seed,
            progress=not args.quiet,
        )
    return cross_validate(
        records,
        lambda tr: train_arm_angle(tr.p, tr.alpha, config).network,
        n_boot=args.bootstrap,
        seed=args.seed,
        progress=not args.quiet,
    )


def _stored(cv: dict) -> dict:
    """The JSON part of a cross-validation (no prediction arrays)."""
    return {k: v for k, v in cv.items() if k != "predictions"}


def _print(cv: dict) -> None:
    def cell(row: dict) -> str:
        return f"{row['rms_deg']:5.1f} [{row['low']:5.1f}, {row['high']:5.1f}]"

    print("rms of the held-out arm angle (deg) [95 % interval, trials resampled]")
    print(f"{'participant':12s} {'network':20s} {'constant':20s} {'Kim (CALIBRATED)':20s}")
    for p, row in cv["participants"].items():
        print(f"{p:12s} {cell(row['network'])} {cell(row['constant'])} {cell(row['kim'])}")
    s = cv["summary"]
    print(f"{'all':12s} {cell(s['network'])} {cell(s['constant'])} {cell(s['kim'])}")
    print(
        f"network - constant {cell(s['network_minus_constant'])}; network - Kim "
        f"{cell(s['network_minus_kim'])} (participants resampled)"
    )
    sp = cv["spread"]
    print(
        f"spread of people about the network: {math.degrees(sp['spread']):.1f} deg (between "
        f"{math.degrees(sp['between']):.1f}, within {math.degrees(sp['within']):.1f}); "
        f"between-person sd {cv['scatter_deg']['network']['sd']:.1f} deg; "
        f"{cv['seconds']:.0f} s"
    )


def _score(args: argparse.Namespace) -> int:
    from wholebody.humanlike.training import import_torch

    import_torch().set_num_threads(args.threads)
    _, records = _records(args)
    cv = _cross_validate(args, records, _config(args), hand=args.hand)
    _print(cv)
    if args.out:
        write_json(args.out, _stored(cv), indent=2, sort_keys=True)
        print(f"scores written to {args.out}")
    return 0


def _comparisons(args: argparse.Namespace, records, cv: dict) -> dict[str, dict]:
    """Other settings under the same cross-validation, paired with the shipped ones."""
    from wholebody.humanlike.arm_angle_scores import paired_comparison

    variants = [
        (f"hidden {','.join(map(str, h))}", _config(args, hidden=tuple(h)), False)
        for h in args.compare_hidden or ()
    ]
    if args.compare_hand:
        variants.append(
            (
                "hidden " + ",".join(map(str, args.hidden)) + " + hand direction "
                "(fingertip - wrist, 3 more inputs)",
                _config(args),
                True,
            )
        )
    out = {}
    for name, config, hand in variants:
        other = _cross_validate(args, records, config, hand=hand)
        out[name] = paired_comparison(cv, other, records, n_boot=args.bootstrap, seed=args.seed)
        print(
            f"{name}: rms {out[name]['rms_deg']:.2f} deg, minus shipped "
            f"{out[name]['minus_base_deg']:+.2f} [{out[name]['low']:+.2f}, "
            f"{out[name]['high']:+.2f}]"
        )
    return out


def _commands(args: argparse.Namespace) -> list[str]:
    common = (
        f"--records {args.records} --hidden {','.join(map(str, args.hidden))} --epochs "
        f"{args.epochs} --lr {args.lr:g} --batch-size {args.batch_size} --weight-decay "
        f"{args.weight_decay:g} --seed {args.seed} --bootstrap {args.bootstrap} --threads "
        f"{args.threads}"
        + (f" --tasks {','.join(args.tasks)}" if args.tasks else "")
        + (f" --recordings {quote(str(args.recordings))}" if args.recordings else "")
    )
    extra = ""
    if args.compare_hidden:
        extra += (
            " --compare-hidden '"
            + ";".join(",".join(map(str, h)) for h in args.compare_hidden)
            + "'"
        )
    if args.compare_hand:
        extra += " --compare-hand"
    if args.no_kim_scatter:
        extra += " --no-kim-scatter"
    return [
        f"wholebody stiffness armangle fit {common}{extra} --out {quote(str(args.out))} "
        f"--card {quote(str(args.card))}",
        "# the cross-validation alone (the tables above), as JSON:",
        f"wholebody stiffness armangle score {common} --out armangle_scores.json",
    ]


def _fit(args: argparse.Namespace) -> int:
    from wholebody.humanlike.arm_angle_card import arm_angle_card
    from wholebody.humanlike.arm_angle_fit import train_arm_angle
    from wholebody.humanlike.arm_angle_scores import kim_calibration_scatter
    from wholebody.humanlike.recordings import load_participants
    from wholebody.humanlike.training import import_torch

    import_torch().set_num_threads(args.threads)
    recs, records = _records(args)
    config = _config(args)
    cv = _cross_validate(args, records, config)
    _print(cv)
    comparisons = _comparisons(args, records, cv)
    kim = {} if args.no_kim_scatter else kim_calibration_scatter(recs, load_participants())
    sp = cv["spread"]
    meta = {
        "date": args.date,
        "data": {
            "tasks": sorted(records.counts),
            "participants": records.participants(),
            "counts": records.counts,
            "records": len(records),
        },
        "cross_validation": _stored(cv),
        "comparisons": comparisons,
        "kim_calibration_scatter": kim,
    }
    result = train_arm_angle(
        records.p,
        records.alpha,
        config,
        spread=(sp["spread"], sp["between"], sp["within"]),
        meta=meta,
    )
    out = result.network.save(args.out)
    print(f"network written to {out} ({result.seconds:.0f} s of training on every participant)")
    if args.card:
        text = arm_angle_card(
            result.network,
            records,
            cv,
            date=args.date,
            commands=_commands(args),
            comparisons=comparisons,
            kim_scatter=kim,
        )
        write_text(args.card, text)
        print(f"data card written to {args.card}")
    return 0


def _options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--recordings",
        default=None,
        help="directory of real recordings "
        "(default: the bundled data/human_reaching/joint_centres)",
    )
    p.add_argument(
        "--tasks",
        type=name_list,
        default=None,
        metavar="NAMES",
        help="only these tasks (default: all: forward,across,drinking,combing)",
    )
    p.add_argument(
        "--records",
        type=int_at_least(100),
        default=20000,
        help="about this many records, every trial alike (default: %(default)s)",
    )
    p.add_argument(
        "--hidden",
        type=int_list,
        default=(8,),
        metavar="SIZES",
        help="hidden layer sizes (default: 8)",
    )
    p.add_argument("--epochs", type=int_at_least(1), default=100)
    p.add_argument("--lr", type=float, default=0.01)
    p.add_argument("--batch-size", type=int_at_least(1), default=256)
    p.add_argument("--weight-decay", type=float, default=0.01, help="AdamW weight decay")
    p.add_argument("--seed", type=int, default=0, help="training and bootstrap seed")
    p.add_argument(
        "--bootstrap",
        type=int_at_least(10),
        default=2000,
        metavar="N",
        help="bootstrap resamples for the intervals (default: %(default)s)",
    )
    p.add_argument("--threads", type=int_at_least(1), default=1, help="torch CPU threads")
    p.add_argument("--quiet", action="store_true", help="no progress bars")


def add_arm_angle_parser(subparsers: argparse._SubParsersAction) -> None:
    """Add ``armangle`` with its ``score`` and ``fit`` subcommands."""
    a = subparsers.add_parser(
        "armangle",
        help="the arm angle people choose: a network of the "
        "normalised wrist, cross-validated by participant",
    )
    sub = a.add_subparsers(dest="armangle_command", required=True, metavar="STEP")
    s = sub.add_parser("score", help="leave-one-participant-out scores against the baselines")
    _options(s)
    s.add_argument(
        "--hand", action="store_true", help="give the network the hand direction too (a comparison)"
    )
    s.add_argument("--out", default=None, help="also write the scores here (JSON)")
    s.set_defaults(func=_score)
    f = sub.add_parser(
        "fit", help="score, then train on every participant and write the network and its data card"
    )
    _options(f)
    f.add_argument(
        "--compare-hidden",
        default=None,
        metavar="CANDIDATES",
        type=lambda t: tuple(int_list(v) for v in t.split(";") if v.strip()),
        help="also score these hidden sizes, ';'-separated (for the card)",
    )
    f.add_argument(
        "--compare-hand",
        action="store_true",
        help="also score a network given the hand direction (for the card)",
    )
    f.add_argument(
        "--no-kim-scatter",
        action="store_true",
        help="skip the Kim calibrations of the between-person scatter (~50 s)",
    )
    f.add_argument(
        "--date", default=datetime.date.today().isoformat(), help="date for the card (YYYY-MM-DD)"
    )
    f.add_argument("--out", default="human_arm_angle.npz", type=Path, help="network file")
    f.add_argument("--card", default=None, type=Path, help="also write the data card here")
    f.set_defaults(func=_fit)
