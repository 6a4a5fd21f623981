"""``python -m engine reconstruct INPUT OUTPUT``: a mesh file from a point-cloud file.

Progress goes to stderr (one updating line on a terminal, a line per 5 % otherwise); the last
line says where the mesh went, its size and the time. The mesh is in the input's coordinates.
Ctrl-C cancels at the next check (a second Ctrl-C stops at once). Nothing is written when the
input is refused, the result is empty or the run is cancelled; the output is checked (writable
folder, known extension, not the input) and the device too before any work, and the write is
atomic (a failed write leaves an existing file as it was). A cloud made in tiles goes to a PLY
output tile by tile (:mod:`..reconstruct_to_file`).
"""

import os
import re
import signal
import sys
import threading
import time

from ..errors import Cancelled, InputError
from ..io import READ_FORMATS, WRITE_FORMATS
from ..settings import ReconstructSettings
from .settings_args import add_settings_arguments


def add_arguments(parser) -> None:
    """Register the command's arguments on an ``argparse`` parser."""
    parser.add_argument("input", help="point cloud or mesh file ("
                                      + ", ".join(f".{f.lower()}" for f in READ_FORMATS) + ")")
    parser.add_argument("output", help="mesh file to write ("
                                       + ", ".join(f".{f.lower()}" for f in WRITE_FORMATS)
                                       + "); never the input")
    add_settings_arguments(parser)
    parser.add_argument("--quiet", action="store_true", help="print only errors")


class _StderrProgress:
    """Progress on stderr: an updating line on a terminal, else a line per 5 % or new stage
    (a stage is the message with its numbers left out)."""

    def __init__(self, quiet: bool):
        self.quiet = quiet
        self.tty = sys.stderr.isatty()
        self.last_step = -1
        self.last_stage = None
        self.dirty = False

    def __call__(self, fraction: float, message: str) -> None:
        if self.quiet:
            return
        percent = 100.0 * fraction
        if self.tty:
            sys.stderr.write(f"\r{percent:5.1f}%  {message[:70]:<70}")
            self.dirty = True
        else:
            stage = re.sub(r"\d[\d,./]*", "#", message)  # "(4/200)" and "(8/200)": one stage
            step = int(percent // 5)
            if step == self.last_step and stage == self.last_stage:
                return
            self.last_step, self.last_stage = step, stage
            sys.stderr.write(f"{percent:5.1f}%  {message}\n")
        sys.stderr.flush()

    def end_line(self) -> None:
        if self.dirty:
            sys.stderr.write("\n")
            self.dirty = False


def run(args) -> int:
    """Read the input, reconstruct, write the output; return the exit status."""
    from ..io import read_point_cloud
    from ..reconstruct_to_file import reconstruct_to_file
    from .preflight import check_device, check_outputs

    started = time.perf_counter()
    settings = ReconstructSettings.from_attributes(args)
    check_outputs([args.output], [args.input])
    check_device(settings.device)
    progress = _StderrProgress(args.quiet)
    stop = threading.Event()

    def interrupt(signum, frame):
        # the first Ctrl-C (or SIGTERM) cancels cleanly at the next check, during the write
        # too; a second one ends at once
        stop.set()
        signal.signal(signum, signal.default_int_handler if signum == signal.SIGINT
                      else signal.SIG_DFL)

    previous = signal.signal(signal.SIGINT, interrupt)
    previous_term = signal.signal(signal.SIGTERM, interrupt)
    try:
        cloud = read_point_cloud(args.input)
        try:
            result = reconstruct_to_file(cloud, args.output, settings, progress, stop.is_set)
        except KeyboardInterrupt:  # the second signal, during the write
            raise Cancelled() from None
        except InputError as error:  # refused: the cloud (NaN, a line...) or an empty result
            progress.end_line()
            raise InputError(f"{os.path.basename(args.input)}: {error}") from None
    finally:
        signal.signal(signal.SIGINT, previous)
        signal.signal(signal.SIGTERM, previous_term)
        progress.end_line()
    if not args.quiet:
        for message in result.messages:
            print(f"note: {message}", file=sys.stderr)
        print(f"wrote {args.output}: {result.stats['vertices']:,} vertices, "
              f"{result.stats['faces']:,} faces from {len(cloud):,} points "
              f"in {time.perf_counter() - started:.1f} s", file=sys.stderr)
    return 0
