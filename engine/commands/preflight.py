"""Checks every command makes before any work: outputs, devices, and what counts as a result.

A run that is bound to fail must fail at once (a missing folder, a read-only folder, an
unsupported extension, an output that is one of the inputs, ``--device cuda`` without a GPU),
not after minutes of reconstruction; and a run that produced nothing must not count as a
success. The CLI commands and the batch script share these checks.
"""

import importlib.util
import os
import sys

from ..errors import InputError
from ..io import check_output_path


def check_outputs(outputs, inputs=()) -> None:
    """Refuse (:class:`InputError`) any output that cannot be written or is one of ``inputs``.

    Also refuses two outputs that are the same file (the second would replace the first).
    """
    outputs = [os.fspath(path) for path in outputs]
    for path in outputs:
        check_output_path(path, inputs)
    from ..io import same_file

    for i, first in enumerate(outputs):
        for second in outputs[i + 1:]:
            if same_file(first, second):
                raise InputError(f"two results would be written to the same file {first} "
                                 f"(and {second}); choose distinct outputs")


def check_device(device: str) -> None:
    """Refuse ``cuda`` quickly when no CUDA GPU can be used; ``auto`` and ``cpu`` always pass.

    Cheap tests come first (is PyTorch installed, is it a CUDA build, is there a CUDA driver),
    so a machine without a GPU answers in milliseconds instead of after importing torch.
    """
    if device != "cuda":
        return
    spec = importlib.util.find_spec("torch")
    if spec is None:
        raise InputError("device 'cuda' needs PyTorch with CUDA, which is not installed; "
                         "use device 'auto' or 'cpu'")
    build = _torch_cuda_build(spec)
    if build is None:
        raise InputError("device 'cuda' was asked for, but the installed PyTorch is a CPU-only "
                         "build; use device 'auto' or 'cpu', or install a CUDA build of PyTorch")
    if not _cuda_driver_present():
        raise InputError("device 'cuda' was asked for, but this machine has no CUDA driver "
                         "(no NVIDIA GPU found); use device 'auto' or 'cpu'")
    from ..devices import resolve_device

    resolve_device(device)  # the full test: torch sees a GPU


def _torch_cuda_build(spec):
    """The CUDA version PyTorch was built for ('12.1'), None for a CPU build, '?' if unknown.

    Read from ``torch/version.py`` without importing torch (which takes seconds).
    """
    for folder in spec.submodule_search_locations or ():
        try:
            with open(os.path.join(folder, "version.py"), encoding="utf-8") as file:
                text = file.read()
        except OSError:
            continue
        for line in text.splitlines():
            if line.startswith("cuda"):
                value = line.split("=", 1)[-1].strip()
                return None if value == "None" else value.strip("'\"")
    return "?"


def _cuda_driver_present() -> bool:
    """Whether the CUDA driver library loads (False when there is no NVIDIA driver)."""
    import ctypes

    names = {"win32": ["nvcuda.dll"], "darwin": []}.get(sys.platform,
                                                          ["libcuda.so.1", "libcuda.so"])
    for name in names:
        try:
            ctypes.CDLL(name)
            return True
        except OSError:
            continue
    return False


MIN_PIECE_FACES = 24
"""A result whose largest piece has fewer faces is junk, not a surface: a real surface spans
many grid cells (the cloud fills its bounding box, whose longest side has >= 32 cells), while
a cloud too sparse for the grid gives a scatter of specks of one to a few faces each."""


def check_result(mesh, what: str = "the reconstruction", radius_mode: str = "fixed") -> None:
    """Refuse an empty or near-empty result (no faces, or only specks: every piece smaller
    than :data:`MIN_PIECE_FACES` faces); such a mesh is an error, not a file to write. The
    advice names the flag that makes the balls larger in ``radius_mode``."""
    sizes = _piece_sizes(mesh.faces, len(mesh.vertices)) if len(mesh.faces) else [0]
    check_pieces(len(mesh.vertices), len(mesh.faces), len(sizes), int(max(sizes)), what,
                 radius_mode)


def check_pieces(vertex_count: int, face_count: int, pieces: int, largest: int,
                 what: str = "the reconstruction", radius_mode: str = "fixed") -> None:
    """:func:`check_result` from a mesh's counts: its vertices, faces, pieces and the faces of
    its largest piece."""
    larger = ("a larger --radius" if radius_mode == "fixed"
              else "a larger --parent-radius (with --custom-range)")
    advice = ("so nothing was written; the cloud may be too sparse or too small for the grid: "
              f"try {larger} or a lower --resolution, or add points")
    if face_count == 0:
        raise InputError(f"{what} found no surface ({vertex_count:,} vertices, 0 faces), "
                         f"{advice}")
    if largest < MIN_PIECE_FACES:
        raise InputError(f"{what} found no surface, only {pieces:,} specks of "
                         f"{largest} faces or fewer ({face_count:,} faces in all), {advice}")


def _piece_sizes(faces, vertex_count: int):
    """Faces per connected piece (faces sharing a vertex are connected)."""
    import numpy as np
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    edges = coo_matrix((np.ones(faces.size), (faces.ravel(), np.roll(faces, 1, axis=1).ravel())),
                       shape=(vertex_count, vertex_count))
    _, labels = connected_components(edges, directed=False)
    return np.bincount(labels[faces[:, 0]])
