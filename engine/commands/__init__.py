"""The command-line commands, one module each with ``add_arguments(parser)`` and ``run(args)``."""

import argparse
import sys

from ..errors import Cancelled, InputError


def run_cli(prog: str, description: str, commands: dict, argv=None) -> int:
    """Parse ``argv`` for one of ``commands`` (``{name: (module, help text)}``) and run it.

    Returns the command's exit status: 2 after an :class:`InputError` (its message on stderr),
    130 after :class:`Cancelled`.
    """
    parser = argparse.ArgumentParser(prog=prog, description=description)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (module, help_text) in commands.items():
        module.add_arguments(sub.add_parser(name, help=help_text, description=help_text))
    args = parser.parse_args(argv)
    try:
        return int(commands[args.command][0].run(args) or 0)
    except InputError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    except Cancelled:
        print("cancelled", file=sys.stderr)
        return 130
