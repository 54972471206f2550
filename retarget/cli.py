"""The ``retarget`` command line. Each subcommand lives in ``retarget/commands/<name>.py`` and
provides ``HELP`` (one line), ``EXAMPLE`` (shown in ``--help``), ``add_arguments(parser)`` and
``run(args) -> int``. Modules are imported lazily so ``retarget --help`` stays fast."""
from __future__ import annotations

import argparse
import importlib
import os
import re
import sys

from .errors import RetargetError

# subcommand name -> module under retarget.commands
COMMANDS = {
    "demo": "demo",
    "synth": "synth",
    "train": "train",
    "transfer": "transfer",
    "animate": "animate",
    "invert": "invert",
    "export-rig": "export_rig",
    "eval": "eval",
    "bench": "bench",
    "calibrate": "calibrate",
}


def _available():
    """(name, module) for every subcommand whose module exists."""
    out = []
    for name, mod in COMMANDS.items():
        try:
            out.append((name, importlib.import_module(f"retarget.commands.{mod}")))
        except ModuleNotFoundError as e:
            if e.name != f"retarget.commands.{mod}":
                raise
    return out


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="retarget",
        description="Mesh-agnostic facial expression retargeting (Neural Face Skinning).",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, module in _available():
        p = sub.add_parser(
            name,
            help=module.HELP,
            description=module.HELP,
            epilog="example:\n  " + module.EXAMPLE.strip().replace("\n", "\n  "),
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


AXIS_OPTIONS = ("--up", "--forward")
_AXIS_VALUE = re.compile(r"^[+-][xyz]$", re.IGNORECASE)


def join_axis_values(argv: list[str]) -> list[str]:
    """``--forward -y`` -> ``--forward=-y``: argparse would take ``-y`` for an option."""
    out = []
    for arg in argv:
        if out and out[-1] in AXIS_OPTIONS and _AXIS_VALUE.match(arg):
            out[-1] = f"{out[-1]}={arg}"
        else:
            out.append(arg)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(join_axis_values(sys.argv[1:] if argv is None else list(argv)))
    if not getattr(args, "_run", None):
        parser.print_help()
        return 1
    try:
        return int(args._run(args) or 0)
    except RetargetError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except MemoryError:
        print(f"error: out of memory running {args.command}; try a smaller mesh or fewer frames",
              file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into e.g. `head`, which closed early: not an error
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":
    sys.exit(main())
