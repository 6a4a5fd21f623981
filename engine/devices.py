"""Which compute device a setting means: ``auto``, ``cpu`` or ``cuda`` (torch, imported lazily)."""

import os
import sys

from .errors import InputError


def _no_nvidia_driver() -> bool:
    """True where no CUDA device can exist: macOS, or no NVIDIA driver on Linux or Windows.

    ``auto`` asks this before importing torch, which takes seconds, on a machine without a GPU.
    """
    if sys.platform == "darwin":
        return True
    if sys.platform.startswith("linux"):
        return not os.path.exists("/proc/driver/nvidia/version")
    if sys.platform == "win32":
        system = os.path.join(os.environ.get("SystemRoot", r"C:\Windows"), "System32")
        return not os.path.exists(os.path.join(system, "nvcuda.dll"))
    return False


def resolve_device(device: str) -> str:
    """``"cpu"`` or ``"cuda"`` for a settings device; ``auto`` picks CUDA when torch sees one.

    Raises
    ------
    InputError
        ``cuda`` was asked for but torch is not installed or sees no CUDA device.
    """
    if device == "cpu" or (device == "auto" and _no_nvidia_driver()):
        return "cpu"
    import importlib.util

    if importlib.util.find_spec("torch") is None:
        if device == "cuda":
            raise InputError("device 'cuda' needs PyTorch with CUDA, which is not installed; "
                             "use device 'auto' or 'cpu'")
        return "cpu"
    import torch

    if torch.cuda.is_available():
        return "cuda"
    if device == "cuda":
        raise InputError("device 'cuda' was asked for but PyTorch sees no CUDA GPU; "
                         "use device 'auto' or 'cpu'")
    return "cpu"
