"""Command-line interface of the lab: ``python -m lab bench ...`` from the repository root.

Training runs as its own modules: ``python -m lab.training.train_backbone`` and
``python -m lab.training.train_selector``.
"""

import sys

from engine.commands import run_cli

from .bench import command as bench
from .bench import scale

COMMANDS = {
    "bench": (bench, "Run a reconstruction method over benchmark shapes; print a table."),
    "scale": (scale, "Reconstruct a generated multi-room floor in tiles beside Poisson."),
}


def main(argv=None) -> int:
    return run_cli("python -m lab", __doc__.splitlines()[0], COMMANDS, argv)


if __name__ == "__main__":
    sys.exit(main())
