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
