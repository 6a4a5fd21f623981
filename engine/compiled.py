"""Optional compiled kernels (numba): which modules of them can be used here.

The engine runs everywhere on numpy; where numba is installed, a few loops that numpy streams
through memory run compiled instead (the mesher's optimisation passes, the field's bricks). A
kernel module imports numba at its top, so importing it fails where numba is missing or refuses
this numpy or Python, and the numpy code runs.
"""

import importlib
import os
import sys


def kernels(module: str):
    """The compiled kernel module ``engine.<module>``, or None: numba missing or refusing this
    numpy, or ``UDF_RECON_KERNELS=numpy`` set (the numpy code everywhere)."""
    if os.environ.get("UDF_RECON_KERNELS", "").lower() == "numpy":
        return None
    if "numba" not in sys.modules and "NUMBA_CACHE_DIR" not in os.environ:
        # numba's cache is keyed by source file, but its entries name the module: the engine
        # imported as ``engine`` (CLI, tests) and inside the extension's package must not share
        os.environ["NUMBA_CACHE_DIR"] = os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                                     "__pycache__", "numba-" + __package__)
    try:
        return importlib.import_module(f"{__package__}.{module}")
    except Exception:  # ImportError, or numba's own error for a numpy it does not accept
        return None
