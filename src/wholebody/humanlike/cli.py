"""``wholebody stiffness dataset | fit | report | armangle``: the pipeline from the shell.

Wire it into the main parser with :func:`add_stiffness_parser`::

    wholebody stiffness dataset --robot mobile_humanoid --out data/stiffness/mobile_humanoid.npz
    wholebody stiffness fit --dataset data/stiffness/mobile_humanoid.npz \\
        --out robots/mobile_humanoid/stiffness.npz --card robots/mobile_humanoid/stiffness_card.md
    wholebody stiffness report --model robots/mobile_humanoid/stiffness.npz \\
        --dataset data/stiffness/mobile_humanoid.npz --out stiffness_report
    wholebody stiffness armangle score | fit ...   (the arm angle people choose:
                                                    wholebody.humanlike.arm_angle_cli)

Each subcommand returns 0 on success; errors are :class:`~wholebody.errors.WholebodyError`
subclasses, which the main command line prints.
"""

from __future__ import annotations

import argparse
import datetime
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from shlex import quote

import numpy as np

from wholebody.errors import DataError
from wholebody.files import write_json, write_text
from wholebody.humanlike.training import DEFAULT_HIDDEN

__all__ = ["add_stiffness_parser"]


def int_at_least(minimum: int) -> Callable[[str], int]:
    """An argparse type: an integer >= ``minimum`` (shared with the arm-angle commands)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"expected an integer >= {minimum}, got {value}")
        return value

    return parse


def int_list(text: str) -> tuple[int, ...]:
    """An argparse type: comma-separated positive integers (layer sizes, ``16,16``)."""
    try:
        out = tuple(int(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated integers, got {text!r}"
        ) from None
    if not out or min(out) < 1:
        raise argparse.ArgumentTypeError(f"expected positive sizes, got {text!r}")
    return out


def name_list(text: str) -> tuple[str, ...]:
    """An argparse type: comma-separated names, blanks dropped (participants, tasks)."""
    return tuple(v.strip() for v in text.split(",") if v.strip())


def _floats(text: str) -> tuple[float, ...]:
    try:
        return tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated numbers, got {text!r}"
        ) from None


def _candidates(args: argparse.Namespace) -> list[dict] | None:
    """The product of --select-hidden and --select-weight-decay (None if neither is given)."""
    if not args.select_hidden and not args.select_weight_decay:
        return None
    hidden = args.select_hidden or (tuple(args.hidden),)
    decay = args.select_weight_decay or (args.weight_decay,)
    return [{"hidden": tuple(h), "weight_decay": float(w)} for h in hidden for w in decay]


def _default_dataset() -> Path:
    from wholebody.resources import data_dir

    return data_dir() / "stiffness" / "mobile_humanoid.npz"


def _dataset(args: argparse.Namespace) -> int:
    from wholebody.humanlike.dataset import DEFAULT_TEST_PARTICIPANTS
    from wholebody.humanlike.mapping import ArmParameters
    from wholebody.humanlike.pipeline import make_dataset
    from wholebody.humanlike.synthetic import DEFAULT_PARTICIPANTS
    from wholebody.robot import load_robot

    robot = load_robot(args.robot)
    params = ArmParameters.from_robot(robot, args.arm)
    n_syn = args.synthetic_participants
    if n_syn > len(DEFAULT_PARTICIPANTS):
        raise DataError(f"--synthetic-participants: at most {len(DEFAULT_PARTICIPANTS)}")
    ds, report, info = make_dataset(
        params,
        recordings_dir=args.recordings,
        real=not args.no_real,
        tasks=args.tasks,
        synthetic=DEFAULT_PARTICIPANTS[:n_syn],
        seed=args.seed,
        n_records=args.records,
        recalibrate=args.calibrate,
        held_out=args.held_out or DEFAULT_TEST_PARTICIPANTS,
        synthetic_out=args.synthetic_out,
        progress=not args.quiet,
    )
    ds.meta["created"] = datetime.date.today().isoformat()
    ds.meta["dataset_options"] = {  # what a data card needs to rebuild this dataset
        "robot": str(args.robot),
        "arm": args.arm,
        "records": args.records,
        "seed": args.seed,
        "synthetic_participants": n_syn,
        "no_real": bool(args.no_real),
        "calibrate": bool(args.calibrate),
        "held_out": list(args.held_out) if args.held_out else None,
        "recordings": None if args.recordings is None else str(args.recordings),
        "tasks": list(args.tasks) if args.tasks else None,
    }
    out = ds.save(args.out)
    print(report.summary())
    if "calibration" in info:
        print(info["calibration"])
    comp = info.get("arm_angle_comparison_deg", {})
    for key, c in comp.items():
        print(
            f"arm angle, {key}: start {c['start_mean']:.1f} +- {c['start_sd']:.1f}, end "
            f"{c['end_mean']:.1f} +- {c['end_sd']:.1f}, all {c['all_mean']:.1f} +- "
            f"{c['all_sd']:.1f} deg, {100 * c['negative_fraction']:.0f} % negative"
        )
    if args.synthetic_out:
        print(f"synthetic recordings written to {args.synthetic_out}")
    print(f"{len(ds)} records written to {out}")
    return 0


def _fit(args: argparse.Namespace) -> int:
    from wholebody.humanlike.dataset import DEFAULT_TEST_PARTICIPANTS, StiffnessDataset
    from wholebody.humanlike.pipeline import PAPER_SCORES, fit_and_evaluate
    from wholebody.humanlike.report import data_card
    from wholebody.humanlike.training import TrainingConfig, import_torch

    import_torch().set_num_threads(args.threads)
    path = Path(args.dataset) if args.dataset else _default_dataset()
    ds = StiffnessDataset.load(path)
    config = TrainingConfig(
        tuple(args.hidden), args.epochs, args.lr, args.batch_size, args.seed, args.weight_decay
    )
    refs = _references(args)
    outcome = fit_and_evaluate(
        ds,
        test_participants=args.test_participants or DEFAULT_TEST_PARTICIPANTS,
        config=config,
        svr=not args.no_svr,
        paper_protocol=args.paper_protocol,
        candidates=_candidates(args),
        references=refs,
        n_boot=args.bootstrap,
        progress=not args.quiet,
    )
    net = outcome.network
    net.meta.update(
        {"date": args.date, "dataset": path.name, "dataset_counts": ds.meta.get("counts", {})}
    )
    out = net.save(args.out)
    s = outcome.scores
    print(f"held-out participants: {', '.join(outcome.test_participants)}")
    for name in ("network", "svr", "mean", *refs):
        if name in s:
            paper = PAPER_SCORES.get(name)
            ref = f"   (paper: R^2 {paper['r2']}, MSE {paper['mse']})" if paper else ""
            print(f"{name:8s} R^2 {s[name]['r2']:.4f}  MSE {s[name]['mse']:.5f} (N m/rad)^2{ref}")
    if outcome.paper_protocol:
        for name, v in outcome.paper_protocol.items():
            print(
                f"paper protocol (300 random records): {name} R^2 {v['r2']:.4f} MSE {v['mse']:.5f}"
            )
    _print_per_participant(net.meta.get("scores_real_held_out", {}))
    print(f"training time {outcome.seconds:.0f} s; network written to {out}")
    if args.card:
        tr = net.meta["training"]
        final = replace(config, hidden=tuple(tr["hidden"]), weight_decay=tr["weight_decay"])
        cmds = card_commands(args, ds.meta, path, final)
        text = data_card(
            net,
            ds,
            date=args.date,
            commands=cmds,
            paper_scores=PAPER_SCORES,
            arm_angle_spread=_arm_angle_spread(),
        )
        write_text(args.card, text)
        print(f"data card written to {args.card}")
    return 0


def _print_per_participant(details: dict) -> None:
    """R^2 per real held-out participant with its interval, one line per model."""
    for name, rows in details.get("per_participant", {}).items():
        cells = "  ".join(
            f"{g} {v['r2']:.3f} [{v['low']:.3f}, {v['high']:.3f}]" for g, v in rows.items()
        )
        print(f"R^2 per real held-out participant, {name}: {cells}")


def _arm_angle_spread() -> dict | None:
    """The shipped arm-angle network's scatter of people (deg), for the card; None without."""
    import math

    from wholebody.arm.human_arm_angle import default_arm_angle_model

    try:
        model = default_arm_angle_model()
    except DataError:
        return None
    return {
        "between": math.degrees(model.spread_between),
        "within": math.degrees(model.spread_within),
    }


def _references(args: argparse.Namespace) -> dict:
    """The networks ``--compare-with`` names, by their ``--compare-label``."""
    from wholebody.arm.network import NetworkStiffness

    if not args.compare_with:
        return {}
    return {args.compare_label: NetworkStiffness.load(args.compare_with)}


def card_commands(args: argparse.Namespace, meta: dict, dataset: Path, config: object) -> list[str]:
    """The shell commands that reproduce a fitted network, for its data card."""
    hidden = ",".join(map(str, config.hidden))  # type: ignore[attr-defined]
    common = (
        f" --epochs {config.epochs} --lr {config.lr} --batch-size {config.batch_size} "  # type: ignore[attr-defined]
        f"--seed {config.seed}"  # type: ignore[attr-defined]
        + (" --paper-protocol" if args.paper_protocol else "")
        + (
            f" --test-participants {','.join(args.test_participants)}"
            if args.test_participants
            else ""
        )
        + (" --no-svr" if args.no_svr else "")
        + (
            f" --compare-with {quote(str(args.compare_with))} --compare-label "
            f"{quote(args.compare_label)}"
            if args.compare_with
            else ""
        )
        + (f" --bootstrap {args.bootstrap}" if args.bootstrap != 2000 else "")
        + f" --threads {args.threads}"
        + f" --out {quote(str(args.out))} --card {quote(str(args.card))}"
    )
    data = quote(f"data/stiffness/{dataset.name}")
    fit = f"wholebody stiffness fit --dataset {data} "
    opts = meta.get("dataset_options")
    if opts:  # every option the dataset was built with (datasets made by this version)
        make = (
            f"wholebody stiffness dataset --robot {quote(opts['robot'])} "
            f"--arm {quote(opts['arm'])} "
            f"--records {opts['records']} --seed {opts['seed']} "
            f"--synthetic-participants {opts['synthetic_participants']}"
            + (" --no-real" if opts["no_real"] else "")
            + (" --calibrate" if opts["calibrate"] else "")
            + (f" --held-out {quote(','.join(opts['held_out']))}" if opts["held_out"] else "")
            + (f" --recordings {quote(opts['recordings'])}" if opts["recordings"] else "")
            + (f" --tasks {','.join(opts['tasks'])}" if opts.get("tasks") else "")
        )
    else:  # an older dataset file: the options it records
        robot = quote(str(meta.get("robot", "mobile_humanoid")))
        make = (
            f"wholebody stiffness dataset --robot {robot} "
            f"--records {meta.get('n_records', 5000)} --seed {meta.get('seed', 0)}"
        )
    cmds = [f"{make} --out {data}"]
    if args.compare_with:
        where = "git show <commit>:robots/<robot>/stiffness.npz > FILE"
        cmds.insert(
            0,
            f"# {args.compare_with}: the network compared with, "
            f"{args.compare_label!r} (a shipped one: {where})",
        )
    wd = config.weight_decay  # type: ignore[attr-defined]
    if args.select_hidden or args.select_weight_decay:
        sel = ""
        if args.select_hidden:
            sel += (
                " --select-hidden '"
                + ";".join(",".join(map(str, h)) for h in args.select_hidden)
                + "'"
            )
        if args.select_weight_decay:
            sel += " --select-weight-decay " + ",".join(f"{w:g}" for w in args.select_weight_decay)
        cmds.append(fit.rstrip() + sel + common)
        cmds.append(f"# the same network without the selection (picked: {hidden}, {wd:g}):")
    cmds.append(fit + f"--hidden {hidden} --weight-decay {wd:g}" + common)
    return cmds


def _report(args: argparse.Namespace) -> int:
    from wholebody.arm.network import NetworkStiffness, default_stiffness
    from wholebody.humanlike.dataset import StiffnessDataset
    from wholebody.humanlike.evaluation import regression_scores
    from wholebody.humanlike.report import plot_workspace

    net = NetworkStiffness.load(args.model) if args.model else default_stiffness()
    if args.dataset:  # a dataset named on the command line must exist
        ds = StiffnessDataset.load(Path(args.dataset))
    else:  # the bundled one, when the data ship with the package
        path = _default_dataset()
        ds = StiffnessDataset.load(path) if path.is_file() else None
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    report: dict = {
        "model": str(args.model or "default"),
        "stored": {
            k: net.meta.get(k)
            for k in (
                "scores_held_out_participants",
                "scores_paper_protocol",
                "svr_params",
                "split",
                "training",
                "date",
            )
        },
    }
    test = net.meta.get("split", {}).get("test_participants") or []
    if ds is not None and test:
        sel = np.isin(ds.participant, test)
        if sel.sum() >= 2:
            report["recomputed_network_held_out"] = regression_scores(
                ds.k[sel], net.predict(ds.wrist[sel])
            )
    steps = [("scores", None), ("plot", None)]
    if not args.quiet:
        from tqdm.auto import tqdm

        steps = tqdm(steps, desc="report", unit="step")
    for step, _ in steps:
        if step == "scores":
            write_json(out / "scores.json", report, indent=2, sort_keys=True)
        else:
            plot_workspace(net, out / "k_workspace.png", ds)
    stored = report["stored"]["scores_held_out_participants"] or {}
    for name, v in stored.items():
        print(f"{name:14s} R^2 {v['r2']:.4f}  MSE {v['mse']:.5f} (N m/rad)^2  (n = {v['n']})")
    if "recomputed_network_held_out" in report:
        v = report["recomputed_network_held_out"]
        print(f"recomputed network on held-out participants: R^2 {v['r2']:.4f} MSE {v['mse']:.5f}")
    print(f"wrote {out / 'scores.json'} and {out / 'k_workspace.png'}")
    return 0


def add_stiffness_parser(subparsers: argparse._SubParsersAction) -> None:
    """Add ``stiffness`` with its ``dataset``, ``fit`` and ``report`` subcommands."""
    today = datetime.date.today().isoformat()
    st = subparsers.add_parser(
        "stiffness", help="human-like stiffness: dataset, network training, report"
    )
    sub = st.add_subparsers(dest="stiffness_command", required=True, metavar="STEP")

    d = sub.add_parser(
        "dataset", help="label recorded arm motions (real; synthetic on request) for a robot"
    )
    d.add_argument("--robot", default="mobile_humanoid", help="bundled name, directory or toml")
    d.add_argument("--arm", default="right", help="arm whose lengths and masses label the data")
    d.add_argument("--records", type=int_at_least(1), default=5000, help="about this many records")
    d.add_argument("--seed", type=int, default=0, help="seed of the synthetic data")
    d.add_argument(
        "--synthetic-participants",
        type=int_at_least(0),
        default=0,
        metavar="N",
        help="add the SYNTHETIC reaches of virtual participants SYN01..SYN0N "
        "(default 0: real recordings only; at most 6)",
    )
    d.add_argument(
        "--tasks",
        type=name_list,
        default=None,
        metavar="NAMES",
        help="only these tasks of the real recordings (default: all: "
        "forward,across,drinking,combing)",
    )
    d.add_argument(
        "--recordings",
        default=None,
        help="directory of real recordings "
        "(default: the bundled data/human_reaching/joint_centres)",
    )
    d.add_argument("--no-real", action="store_true", help="synthetic data only")
    d.add_argument(
        "--calibrate",
        action="store_true",
        help="re-fit the arm-angle model on the real recordings of the participants not held out",
    )
    d.add_argument(
        "--held-out",
        type=name_list,
        default=None,
        metavar="IDS",
        help="participants kept out of the calibration, to be held out when the "
        "network is scored (default: fit's default test participants)",
    )
    d.add_argument(
        "--synthetic-out",
        default=None,
        metavar="DIR",
        help="also write the synthetic recordings there (.npz)",
    )
    d.add_argument("--out", default="stiffness_dataset.npz", help="dataset file to write")
    d.add_argument("--quiet", action="store_true", help="no progress bars")
    d.set_defaults(func=_dataset)

    f = sub.add_parser("fit", help="train the network and the SVR, score held-out participants")
    f.add_argument("--dataset", default=None, help="dataset file (default: the bundled one)")
    f.add_argument(
        "--test-participants",
        type=name_list,
        default=None,
        metavar="IDS",
        help="comma-separated held-out participants (default: ADL003,ADL008,ADL011)",
    )
    f.add_argument(
        "--hidden",
        type=int_list,
        default=DEFAULT_HIDDEN,
        metavar="SIZES",
        help="hidden layer sizes (default: %(default)s)",
    )
    f.add_argument(
        "--select-hidden",
        type=lambda t: tuple(int_list(v) for v in t.split(";") if v.strip()),
        default=None,
        metavar="CANDIDATES",
        help="choose the hidden sizes by grouped 3-fold CV on the training participants among "
        "';'-separated candidates, e.g. '4,4;8;8,8' (overrides --hidden; one-standard-error "
        "rule, see wholebody.humanlike.pipeline.select_model)",
    )
    f.add_argument(
        "--select-weight-decay",
        type=_floats,
        default=None,
        metavar="VALUES",
        help="also choose the weight decay among comma-separated values, e.g. 0,1e-3,1e-2",
    )
    f.add_argument(
        "--weight-decay",
        type=float,
        default=0.0,
        help="AdamW weight decay (0: plain Adam, the paper's)",
    )
    f.add_argument("--epochs", type=int_at_least(1), default=1000)
    f.add_argument("--lr", type=float, default=0.01)
    f.add_argument("--batch-size", type=int_at_least(1), default=32)
    f.add_argument("--seed", type=int, default=0)
    f.add_argument("--threads", type=int_at_least(1), default=1, help="torch CPU threads")
    f.add_argument("--no-svr", action="store_true", help="skip the SVR baseline")
    f.add_argument(
        "--paper-protocol",
        action="store_true",
        help="also score the paper's split (300 random records), for comparison",
    )
    f.add_argument(
        "--compare-with",
        default=None,
        metavar="FILE",
        help="also score this network (e.g. the one shipped before) on the same "
        "held-out records, for the card; it must have held them out too",
    )
    f.add_argument(
        "--compare-label",
        default="previous network",
        metavar="TEXT",
        help="its name in the card (default: %(default)s)",
    )
    f.add_argument(
        "--bootstrap",
        type=int_at_least(10),
        default=2000,
        metavar="N",
        help="bootstrap resamples of the per-participant intervals",
    )
    f.add_argument("--card", default=None, help="also write a markdown data card here")
    f.add_argument("--date", default=today, help="date for the card (YYYY-MM-DD)")
    f.add_argument("--out", default="stiffness.npz", help="network file to write")
    f.add_argument("--quiet", action="store_true", help="no progress bars")
    f.set_defaults(func=_fit)

    r = sub.add_parser("report", help="scores and a plot of k over the workspace")
    r.add_argument("--model", default=None, help="network file (default: the shipped one)")
    r.add_argument("--dataset", default=None, help="dataset file (default: the bundled one)")
    r.add_argument("--out", default="stiffness_report", help="directory for the report")
    r.add_argument("--quiet", action="store_true", help="no progress bars")
    r.set_defaults(func=_report)

    from wholebody.humanlike.arm_angle_cli import add_arm_angle_parser  # it imports this module

    add_arm_angle_parser(sub)
