"""Optional compiled kernels (numba): which modules of them can be used here.

The engine runs everywhere on numpy; where numba is installed, a few loops that numpy streams
through memory run compiled instead (the mesher's optimisation passes, the field's bricks). A
kernel module imports numba at its top, so importing it fails where numba is missing or refuses
this numpy or Python, and the numpy code runs.
"""

import importlib
import os


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
    failure only means the mesher loads the kernels itself."""
    if os.environ.get("UDF_RECON_KERNELS", "").lower() == "numpy":
        return
    import threading

    threading.Thread(target=_mesh_a_small_sphere, name="udf-kernels-warm-up",
                     daemon=True).start()


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
