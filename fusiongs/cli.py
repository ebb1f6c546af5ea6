"""``fusiongs <verb>``: the command line and nothing else.

Each verb lives in ``fusiongs.commands.<verb>`` and defines ``HELP`` (one line),
``add_arguments(parser)`` and ``run(args) -> int``. Verb modules import heavy packages inside
``run`` so that ``fusiongs --help`` stays fast.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from fusiongs import __version__
from fusiongs.errors import FusionGSError

VERBS: tuple[str, ...] = ("demo", "simulate", "convert", "inspect", "calibrate", "edi", "deblur", "render",
                         "view", "eval")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fusiongs",
        description="Blurry frames + events -> sharp frames, sharp video and a 3D Gaussian scene.",
    )
    parser.add_argument("--version", action="version", version=f"fusiongs {__version__}")
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    for verb in VERBS:
        module = importlib.import_module(f"fusiongs.commands.{verb}")
        p = sub.add_parser(verb, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra:
        # ``key=value`` config overrides may follow options; anything else is an error.
        bad = [a for a in extra if "=" not in a or a.startswith("-")]
        if bad or not hasattr(args, "overrides"):
            parser.error(f"unrecognized arguments: {' '.join(bad or extra)}")
        args.overrides = list(args.overrides or []) + extra
    if args.verb is None:
        parser.print_help()
        return 2
    try:
        return int(args._run(args) or 0)
    except FusionGSError as e:
        print(f"fusiongs {args.verb}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"fusiongs {args.verb}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
