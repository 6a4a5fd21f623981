"""Progress reporting and cooperative cancelling, shared by every long-running stage.

A stage takes ``progress(fraction, message)`` and ``cancel() -> bool`` callables. It reports
fractions in [0, 1] of its own work and calls :func:`check_cancel` often enough (every ~0.5 s of
work) that a cancel request is honoured within a second or two.
"""

from typing import Callable, Optional

from .errors import Cancelled

ProgressFn = Callable[[float, str], None]
CancelFn = Callable[[], bool]


def no_progress(fraction: float, message: str) -> None:
    """A progress callback that ignores everything."""


def check_cancel(cancel: Optional[CancelFn]) -> None:
    """Raise :class:`Cancelled` when ``cancel()`` asks to stop."""
    if cancel is not None and cancel():
        raise Cancelled("cancelled by the user")


def sub_progress(progress: Optional[ProgressFn], start: float, end: float) -> ProgressFn:
    """Map a stage's own [0, 1] progress onto [start, end] of the caller's progress."""
    if progress is None:
        return no_progress

    def report(fraction: float, message: str) -> None:
        fraction = min(max(float(fraction), 0.0), 1.0)
        progress(start + (end - start) * fraction, message)

    return report
