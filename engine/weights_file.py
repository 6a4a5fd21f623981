"""The weights file format shared by the shipped networks: one ``.npz`` of float32 arrays named
as in the torch state dict, plus ``config_json`` holding {"config": ..., "meta": ...}."""

import json
from pathlib import Path
from typing import Dict, Optional, Tuple, Union

import numpy as np


def save_weights(module, path: Union[str, Path], meta: Optional[Dict] = None) -> Path:
    """Write a torch module's parameters and its ``config`` attribute (+ meta) atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = {k: v.detach().cpu().numpy().astype(np.float32) for k, v in module.state_dict().items()}
    arrays["config_json"] = np.array(json.dumps({"config": module.config, "meta": meta or {}}))
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez(tmp, **arrays)
    tmp.replace(path)
    return path


def read_weights(path: Union[str, Path]) -> Tuple[Dict[str, np.ndarray], Dict]:
    """(parameters by name, header with "config" and "meta") from a weights file."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"network weights not found: {path}")
    with np.load(path, allow_pickle=False) as data:
        header = json.loads(str(data["config_json"]))
        params = {k: data[k] for k in data.files if k != "config_json"}
    return params, header
