"""``python -m engine reconstruct INPUT OUTPUT``: a mesh file from a point-cloud file.

Progress goes to stderr (one updating line on a terminal, a line per 5 % otherwise); the last
line says where the mesh went, its size and the time. The mesh is in the input's coordinates.
Ctrl-C cancels at the next check (a second Ctrl-C stops at once). Nothing is written when the
input is refused, the result is empty or the run is cancelled; the output is checked (writable
folder, known extension, not the input) and the device too before any work, and the write is
atomic (a failed write leaves an existing file as it was).
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
    from ..io import read_point_cloud, write_mesh
    from ..reconstruct import reconstruct
    from .preflight import check_device, check_outputs, check_result

    started = time.perf_counter()
    settings = ReconstructSettings.from_attributes(args)
    check_outputs([args.output], [args.input])
    check_device(settings.device)
    progress = _StderrProgress(args.quiet)
    stop = threading.Event()

    def interrupt(signum, frame):
        # the first Ctrl-C (or SIGTERM) cancels cleanly at the next check; a second one ends
        # at once
        stop.set()
        signal.signal(signum, signal.default_int_handler if signum == signal.SIGINT
                      else signal.SIG_DFL)

    previous = signal.signal(signal.SIGINT, interrupt)
    previous_term = signal.signal(signal.SIGTERM, interrupt)
    try:
        cloud = read_point_cloud(args.input)
        try:
            result = reconstruct(cloud, settings, progress, stop.is_set)
        except InputError as error:  # the cloud is refused (NaN, too few points, a line...)
            progress.end_line()
            raise InputError(f"{os.path.basename(args.input)}: {error}") from None
    finally:
        signal.signal(signal.SIGINT, previous)
        signal.signal(signal.SIGTERM, previous_term)
        progress.end_line()
    if not args.quiet:
        for message in result.messages:
            print(f"note: {message}", file=sys.stderr)
    check_result(result.mesh)
    _write_interruptibly(args.output, result.mesh, write_mesh)
    if not args.quiet:
        print(f"wrote {args.output}: {len(result.mesh.vertices):,} vertices, "
              f"{len(result.mesh.faces):,} faces from {len(cloud):,} points "
              f"in {time.perf_counter() - started:.1f} s", file=sys.stderr)
    return 0


def _write_interruptibly(path, mesh, write_mesh) -> None:
    """Write the mesh; Ctrl-C or SIGTERM during the write stops it, removes the partial
    temporary file and leaves any existing output as it was (raises Cancelled)."""

    def stop_writing(signum, frame):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, stop_writing)
    try:
        write_mesh(path, mesh)
    except KeyboardInterrupt:
        raise Cancelled() from None
    finally:
        signal.signal(signal.SIGTERM, previous)
