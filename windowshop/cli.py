"""The `windowshop` command: one short function per subcommand.

Heavy imports (torch, pycolmap, the service) happen inside each function so `--help` is instant.
Errors the user can fix are raised as `windowshop.errors.UserError` and printed without a traceback.
"""

from __future__ import annotations

import argparse
import sys

from windowshop.errors import UserError


def _scene_options(args: argparse.Namespace):
    from windowshop.config import SceneOptions

    return SceneOptions(downscale=args.downscale, max_side=args.max_side, views=args.views,
                        test_views=args.test_views, background=args.background)


def _add_scene_flags(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("scene loading")
    g.add_argument("--downscale", type=float, default=1.0, help="divide the resolution by K")
    g.add_argument("--max-side", type=int, default=None, help="resize so the longer side is at most N")
    g.add_argument("--views", type=int, default=None, help="keep N training views spread evenly")
    g.add_argument("--test-views", type=int, default=None, help="keep K evenly spaced test views")
    g.add_argument("--background", choices=["white", "black", "alpha"], default="white",
                   help="background for sources with alpha")


def cmd_inspect(args: argparse.Namespace) -> None:
    from windowshop.scene.inspect import inspect_command

    inspect_command(args.path, _scene_options(args), as_json=args.json, plot=args.plot)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="windowshop", description=__doc__.splitlines()[0])
    parser.add_argument("-v", "--verbose", action="store_true", help="more logging")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("inspect", help="summarise a posed scene (any supported format)")
    p.add_argument("path")
    p.add_argument("--json", action="store_true", help="print the machine-readable summary")
    p.add_argument("--plot", default=None, help="draw the cameras around the object into FILE.png")
    _add_scene_flags(p)
    p.set_defaults(func=cmd_inspect)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        args.func(args)
    except UserError as err:
        print(f"windowshop {args.command}: error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
