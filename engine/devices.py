"""Which compute device a setting means: ``auto``, ``cpu`` or ``cuda`` (torch, imported lazily)."""

from .errors import InputError


def resolve_device(device: str) -> str:
    """``"cpu"`` or ``"cuda"`` for a settings device; ``auto`` picks CUDA when torch sees one.

    Raises
    ------
    InputError
        ``cuda`` was asked for but torch is not installed or sees no CUDA device.
    """
    if device == "cpu":
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
