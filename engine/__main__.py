"""Command-line interface: ``python -m engine COMMAND ...`` from the repository root.

Each command lives in ``engine/commands/<name>.py`` with ``add_arguments(parser)`` and
``run(args) -> int``; a command's heavy modules are imported only when it runs (torch stays lazy).
"""

import importlib
import sys

from .commands import run_cli

COMMANDS = {
    "reconstruct": ("reconstruct", "Reconstruct a mesh from a point-cloud file."),
    "mesh-udf": ("mesh_udf", "Mesh an unsigned distance grid (.npz with udf, origin, spacing)."),
    "metrics": ("metrics", "Compare a predicted mesh with a ground-truth mesh (prints JSON)."),
}


def main(argv=None) -> int:
    commands = {name: (importlib.import_module(f".commands.{module}", __package__), help_text)
                for name, (module, help_text) in COMMANDS.items()}
    return run_cli("python -m engine", __doc__.splitlines()[0], commands, argv)


if __name__ == "__main__":
    sys.exit(main())
