"""Command-line interface: ``python -m engine COMMAND ...`` from the repository root.

Each command lives in ``engine/commands/<name>.py`` with ``add_arguments(parser)`` and
``run(args) -> int``; modules are imported only when their command runs (torch stays lazy).
"""

import argparse
import importlib
import sys

from .errors import Cancelled, InputError

COMMANDS = {
    "reconstruct": ("reconstruct", "Reconstruct a mesh from a point-cloud file."),
    "mesh-udf": ("mesh_udf", "Mesh an unsigned distance grid (.npz with udf, origin, spacing)."),
    "metrics": ("metrics", "Compare a predicted mesh with a ground-truth mesh (prints JSON)."),
    "bench": ("bench", "Run a reconstruction method over benchmark shapes; print a table."),
}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m engine", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    modules = {}
    for name, (module_name, help_text) in COMMANDS.items():
        module = importlib.import_module(f".commands.{module_name}", __package__)
        modules[name] = module
        module.add_arguments(sub.add_parser(name, help=help_text, description=help_text))
    args = parser.parse_args(argv)
    try:
        return int(modules[args.command].run(args) or 0)
    except InputError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    except Cancelled:
        print("cancelled", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
