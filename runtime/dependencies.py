"""The Python packages the extension needs, and whether a GPU can be used.

The one table of runtime dependencies: the Reconstruct button checks it before any work, the panel
shows a red line for each missing package and the preferences list it. To add or drop a
dependency, edit :data:`DEPENDENCIES` and nothing else.

No bpy and no Blender classes here, so the panel, the preferences and the operator can all use it.
Finding a package imports nothing (``importlib.util.find_spec``), so it is cheap enough to run on
every redraw and a broken package cannot break the panel.
"""

import importlib.metadata
import importlib.util
import os
import subprocess
import sys
import threading

# (import name, the name users install it by, what it is for, required to reconstruct)
DEPENDENCIES = (
    ("numpy", "numpy", "arrays (ships with Blender)", True),
    ("scipy", "scipy", "neighbour search", True),
    ("skimage", "scikit-image", "marching cubes", True),
    ("laspy", "laspy", "reading LAS/LAZ scans (optional)", False),
    ("trimesh", "trimesh", "STL and glTF files in batch runs (optional)", False),
    ("numba", "numba", "a faster mesher and network on the CPU (optional)", False),
    ("torch", "torch", "computing on an NVIDIA GPU (optional)", False),
)


def is_found(module: str) -> bool:
    """Whether ``module`` can be imported (without importing it)."""
    if module in sys.modules:
        return True
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        return False


def install_name(module: str) -> str:
    """The name users install the package that provides ``module`` by (``skimage`` -> scikit-image);
    the top-level module name when it is not in the table."""
    top = module.split(".")[0]
    for name, distribution, _, _ in DEPENDENCIES:
        if name == top:
            return distribution
    return top


def missing_packages(optional: bool = False) -> list:
    """The install names of the required packages (and with ``optional``, of the optional ones
    too) that cannot be found, in table order."""
    return [distribution for module, distribution, _, required in DEPENDENCIES
            if (required or optional) and not is_found(module)]


def missing_message(missing) -> str:
    """What to tell the user when ``missing`` (install names) are not there."""
    names = ", ".join(missing)
    plural = "s" if len(missing) > 1 else ""
    return (f"Missing Python package{plural}: {names}. Nothing was computed. Click Install "
            f"Missing Packages in Preferences > Add-ons > UDF Reconstruction, or install the "
            f"extension zip made for your platform and Blender version (it bundles them).")


def dependency_status() -> list:
    """One ``(install name, version or None, purpose, required)`` per dependency (None: not
    found)."""
    rows = []
    for module, distribution, purpose, required in DEPENDENCIES:
        version = None
        if is_found(module):
            try:
                version = importlib.metadata.version(distribution)
            except importlib.metadata.PackageNotFoundError:
                version = "found"
        rows.append((distribution, version, purpose, required))
    return rows


# --- GPU ------------------------------------------------------------------------------------------

_gpu = {"known": False, "available": False, "name": "", "thread": None}
_gpu_lock = threading.Lock()


_PROBE = ("import torch\n"
          "if torch.cuda.is_available():\n"
          "    print('cuda', torch.cuda.get_device_name(0))\n")


def _ask_torch() -> tuple:
    """``(available, device name)`` from torch, asked in a child Python process.

    Importing torch takes seconds and loads large native libraries; doing that on a thread while
    Blender runs operators on the main one can crash Blender, so unless torch is already loaded
    the question goes to a separate interpreter that sees the same packages.
    """
    if "torch" in sys.modules:
        torch = sys.modules["torch"]
        if torch.cuda.is_available():
            return True, torch.cuda.get_device_name(0)
        return False, ""
    environment = dict(os.environ, PYTHONPATH=os.pathsep.join(path for path in sys.path if path))
    flags = getattr(subprocess, "CREATE_NO_WINDOW", 0)  # no console window flashing on Windows
    try:
        answer = subprocess.run([sys.executable, "-c", _PROBE], env=environment,
                                capture_output=True, text=True, timeout=300, creationflags=flags)
    except (OSError, subprocess.SubprocessError):
        return False, ""
    words = answer.stdout.strip().split(" ", 1) if answer.returncode == 0 else []
    if words and words[0] == "cuda":
        return True, words[1] if len(words) > 1 else ""
    return False, ""


def _probe_gpu() -> None:
    """Find out whether torch sees a CUDA GPU, and keep the answer."""
    try:
        available, name = _ask_torch()
    except Exception:  # a broken torch means no GPU for us, not a broken panel
        available, name = False, ""
    with _gpu_lock:
        _gpu.update(known=True, available=available, name=name)


def gpu_available(wait: bool = False):
    """True when torch sees a CUDA GPU, False when not (or torch is missing), None while unknown.

    Without torch the answer is immediate. With torch it is found out once, by a child process
    watched from a background thread (importing torch takes seconds, too long for a redraw);
    ``wait=True`` finds it out now instead. The answer is kept: GPUs do not come and go while
    Blender runs.
    """
    with _gpu_lock:
        if _gpu["known"]:
            return _gpu["available"]
        if not is_found("torch"):
            _gpu.update(known=True, available=False, name="")
            return False
        thread = _gpu["thread"]
        if thread is None and not wait:
            thread = threading.Thread(target=_probe_gpu, name="udfr_gpu_probe", daemon=True)
            _gpu["thread"] = thread
            thread.start()
    if wait:
        if thread is not None:
            thread.join()
        else:
            _probe_gpu()
        return _gpu["available"]
    return None


def gpu_text() -> str:
    """One short line about the GPU, for the panel and the preferences."""
    available = gpu_available()
    if available is None:
        return "Looking for a GPU..."
    if available:
        return f"GPU: {_gpu['name']}" if _gpu["name"] else "GPU found"
    if not is_found("torch"):
        return "No GPU found (needs PyTorch with CUDA); the CPU is used"
    return "No GPU found; the CPU is used"

