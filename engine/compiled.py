"""Optional compiled kernels (numba): which modules of them can be used here.

The engine runs everywhere on numpy; where numba is installed, a few loops that numpy streams
through memory run compiled instead (the mesher's optimisation passes, the field's bricks). A
kernel module imports numba at its top, so importing it fails where numba is missing or refuses
this numpy or Python, and the numpy code runs.
"""

import importlib
import os
import threading
from typing import Optional

from .progress import CancelFn, ProgressFn, check_cancel

_warm_up: Optional[threading.Thread] = None  # the warm-up thread, once started


def kernels(module: str):
    """The compiled kernel module ``engine.<module>``, or None: numba missing or refusing this
    numpy, or ``UDF_RECON_KERNELS=numpy`` set (the numpy code everywhere)."""
    if os.environ.get("UDF_RECON_KERNELS", "").lower() == "numpy":
        return None
    try:
        return importlib.import_module(f"{__package__}.{module}")
    except Exception:  # ImportError, or numba's own error for a numpy it does not accept
        return None


def warm_up() -> None:
    """Load the compiled kernels in a background thread while other work runs: numba's import
    and its cached machine code take a second or two per process (and the first run on a machine
    compiles them), which the mesher would otherwise wait for. It meshes a small sphere, which
    calls every kernel with the argument types of a real run; its result is dropped, and a
    failure only means the mesher loads the kernels itself. Once per process."""
    global _warm_up
    if _warm_up is not None or os.environ.get("UDF_RECON_KERNELS", "").lower() == "numpy":
        return
    _warm_up = threading.Thread(target=_mesh_a_small_sphere, name="udf-kernels-warm-up",
                                daemon=True)
    _warm_up.start()


def wait_for_warm_up(progress: ProgressFn, cancel: Optional[CancelFn], fraction: float) -> None:
    """Before the mesher's first kernel: while the warm-up still runs (the first run on a
    machine compiles for a while), say so and wait, checking ``cancel``."""
    thread = _warm_up
    if thread is None or thread is threading.current_thread() or not thread.is_alive():
        return
    progress(fraction, "loading the mesher's compiled loops (the first run on a computer also "
                       "compiles them, once)")
    while thread.is_alive():
        check_cancel(cancel)
        thread.join(0.2)


def _mesh_a_small_sphere() -> None:
    try:
        if kernels("meshing.optimize_kernels") is None:
            return
        import numpy as np

        from .meshing import MeshingSettings, extract_surface
        from .udf_grid import UDFGrid

        axis = np.linspace(-1.0, 1.0, 16)
        x, y, z = np.meshgrid(axis, axis, axis, indexing="ij")
        udf = np.abs(np.sqrt(x * x + y * y + z * z) - 0.6)
        extract_surface(UDFGrid(udf, (-1.0, -1.0, -1.0), axis[1] - axis[0]), MeshingSettings())
    except Exception:
        pass
