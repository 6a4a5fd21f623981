"""Atomic file writes: a hidden temporary file beside the target, flushed to disk, then
``os.replace``. A failed or interrupted write leaves the previous file as it was."""

import os
import secrets
import shutil
from typing import Callable, Tuple


def write_atomically(path: str, write: Callable) -> None:
    """Call ``write(file)`` on a new hidden file beside ``path``, then move it over ``path``.

    The temporary file replaces the target only once ``write`` has returned and the bytes are
    flushed to disk (fsync). When anything fails (a full disk, a file-size limit, an exception,
    Ctrl-C) the temporary file is removed and an existing target is left exactly as it was.
    A process killed outright may leave the hidden ``.NAME.*.tmp`` file behind, never a
    partial target. The replaced file keeps its permissions.

    Raises
    ------
    OSError
        The folder does not exist or a file cannot be created or written there.
    """
    folder = os.path.dirname(os.path.abspath(path))
    temporary, descriptor = temporary_file(folder, os.path.basename(path))
    try:
        with os.fdopen(descriptor, "wb") as file:
            write(file)
            file.flush()
            os.fsync(file.fileno())
        if os.path.exists(path):
            shutil.copymode(path, temporary)
        os.replace(temporary, path)
        temporary = None
    finally:
        if temporary is not None:
            remove_quietly(temporary)


def same_file(first, second) -> bool:
    """Whether two paths name the same file: the same inode when both exist, else the same
    resolved path (symbolic links followed, case folded where the system folds it)."""
    try:
        return os.path.samefile(first, second)
    except OSError:
        pass
    resolved = [os.path.normcase(os.path.realpath(os.fspath(p))) for p in (first, second)]
    return resolved[0] == resolved[1]


def temporary_file(folder: str, name: str) -> Tuple[str, int]:
    """Create a new hidden file ``.NAME.<random>.tmp`` in ``folder`` -> (path, descriptor).

    Created with mode 0o666 less the umask, like ``open``; never replaces an existing file.
    """
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)
    temporary = os.path.join(folder, f".{name}.{secrets.token_hex(6)}.tmp")
    return temporary, os.open(temporary, flags, 0o666)


def remove_quietly(path: str) -> None:
    try:
        os.remove(path)
    except OSError:
        pass
