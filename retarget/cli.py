"""The ``retarget`` command line. Each subcommand lives in ``retarget/commands/<name>.py`` and
provides ``HELP`` (one line), ``EXAMPLE`` (shown in ``--help``), ``add_arguments(parser)`` and
``run(args) -> int``. Modules are imported lazily so ``retarget --help`` stays fast."""
from __future__ import annotations

import argparse
import importlib
import os
import re
import sys
import warnings

from .errors import RetargetError, RetargetWarning

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


class Parser(argparse.ArgumentParser):
    """argparse with the project's one-line user errors: a bad option raises RetargetError
    (``error: retarget CMD: <problem> (see retarget CMD --help)``, exit status 2)."""

    def error(self, message):
        raise RetargetError(f"{self.prog}: {message} (see {self.prog} --help)")


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
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


MAX_ERROR_CHARS = 1000  # a message quoting a hostile file is cut to this


def one_line(message) -> str:
    """A message as one line of at most MAX_ERROR_CHARS characters."""
    text = " ".join(str(message).split())
    return text if len(text) <= MAX_ERROR_CHARS else text[:MAX_ERROR_CHARS - 3] + "..."


def main(argv: list[str] | None = None) -> int:
    """Run one command. User errors (RetargetError) print ``error: <message>`` as the last line of
    stderr and return 2. The project's warnings (RetargetWarning) print ``warning: <message>`` at
    once; other Python warnings (numpy, torch) are held and printed after a command that succeeds,
    never before the error of one that fails."""
    parser = build_parser()
    held = []

    def show(message, category, filename, lineno, file=None, line=None):
        text = f"warning: {one_line(message)}"
        if issubclass(category, RetargetWarning):
            print(text, file=sys.stderr)
        elif text not in held:
            held.append(text)

    with warnings.catch_warnings():
        warnings.showwarning = show
        try:
            args = parser.parse_args(join_axis_values(sys.argv[1:] if argv is None else list(argv)))
            if not getattr(args, "_run", None):
                parser.print_help()
                return 1
            status = int(args._run(args) or 0)
        except RetargetError as e:
            print(f"error: {one_line(e)}", file=sys.stderr)
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
    for text in held:
        print(text, file=sys.stderr)
    return status


if __name__ == "__main__":
    sys.exit(main())
