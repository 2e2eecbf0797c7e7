"""The ``wholebody`` command line."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from wholebody.errors import WholebodyError

__all__ = ["main"]


def _info(args: argparse.Namespace) -> int:
    from wholebody.robot import available_robots, load_robot

    if args.list:
        print("\n".join(available_robots()))
        return 0
    print(load_robot(args.robot).summary())
    return 0


def _demo(args: argparse.Namespace) -> int:
    from wholebody.robot import load_robot

    print(load_robot("mobile_humanoid").summary())
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="wholebody",
        description="Whole-body control of highly redundant mobile humanoids.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    info = sub.add_parser("info", help="describe a robot (bundled name, directory or robot.toml)")
    info.add_argument("robot", nargs="?", default="mobile_humanoid")
    info.add_argument("--list", action="store_true", help="list the bundled robots")
    info.set_defaults(func=_info)
    demo = sub.add_parser("demo", help="run the demo scenario")
    demo.set_defaults(func=_demo)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except WholebodyError as exc:
        print(f"wholebody: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
