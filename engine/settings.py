"""Settings of one reconstruction: one dataclass shared by the CLI, Blender, batch and benchmark."""

import math
import numbers
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields

from .errors import InputError
from .outliers import DEFAULT_RATIO as DEFAULT_OUTLIER_RATIO
from .outliers import POLICIES as OUTLIER_POLICIES

RADIUS_MODES = ("fixed", "curvature", "learned")
DEVICES = ("auto", "cpu", "cuda")
MAX_SEED = 2 ** 32 - 1
"""Seeds are whole numbers in [0, MAX_SEED] (what numpy's generators accept)."""


@dataclass
class ReconstructSettings:
    """How to reconstruct. All lengths are in the unit frame (bounding box longest side 1).

    radius_mode: how the backbone's ball radius is chosen per query: ``fixed`` (one radius, as
        LoSF-UDF), ``curvature`` (smaller where the surface bends, as GeoLA) or ``learned``
        (the selector network predicts it).
    radius: the ball radius of ``fixed`` mode.
    parent_radius: R, the radius of the parent ball the curvature and learned modes look at.
    rho_min, rho_max: the per-query radius stays in [rho_min * R, rho_max * R].
    resolution: grid cells along the longest side of the bounding box.
    device: ``auto`` (CUDA when available), ``cpu`` or ``cuda``.
    seed: every random choice is drawn from this seed, so results repeat on CPU.
    min_component_faces: drop output pieces with fewer faces (0 keeps everything).
    outliers: what to do with points isolated from the surface (:mod:`.outliers`): ``drop``
        them before reconstructing, ``keep`` them, or ``auto``: drop them when they are at
        least 1 % of the cloud (a scan with strays), else keep them (on a clean scan the few
        points flagged are more often the sparse edge of the scan).
    outlier_ratio: a point is isolated when its spacing to its nearest neighbours is more than
        this many times that of the points around it.
    """

    radius_mode: str = "fixed"
    radius: float = 0.018
    parent_radius: float = 0.024
    rho_min: float = 0.5
    rho_max: float = 1.0
    resolution: int = 256
    device: str = "auto"
    seed: int = 0
    min_component_faces: int = 0
    outliers: str = "auto"
    outlier_ratio: float = DEFAULT_OUTLIER_RATIO

    def validate(self) -> "ReconstructSettings":
        """Raise :class:`InputError` with a clear message when a setting is out of range or of
        the wrong type (a string resolution, a float or negative seed, ...)."""
        for item in fields(self):
            _check_type(item.name, getattr(self, item.name), type(item.default))
        if self.radius_mode not in RADIUS_MODES:
            raise InputError(f"radius mode must be one of {', '.join(RADIUS_MODES)}, "
                             f"not {self.radius_mode!r}")
        if self.device not in DEVICES:
            raise InputError(f"device must be one of {', '.join(DEVICES)}, not {self.device!r}")
        if not 0.001 <= self.radius <= 0.2:
            raise InputError(f"radius {self.radius} is outside [0.001, 0.2] (unit frame)")
        if not 0.001 <= self.parent_radius <= 0.2:
            raise InputError(f"parent radius {self.parent_radius} is outside [0.001, 0.2]")
        if not 0.05 <= self.rho_min <= self.rho_max <= 1.0:
            raise InputError(f"need 0.05 <= rho_min <= rho_max <= 1, got "
                             f"rho_min={self.rho_min}, rho_max={self.rho_max}")
        if not 32 <= self.resolution <= 1024:
            raise InputError(f"resolution {self.resolution} is outside [32, 1024]")
        if not 0 <= self.seed <= MAX_SEED:
            raise InputError(f"seed {self.seed} is outside [0, {MAX_SEED}]; give a whole number "
                             f"from 0 to {MAX_SEED}")
        if self.min_component_faces < 0:
            raise InputError(f"min_component_faces must be >= 0, not {self.min_component_faces}")
        if self.outliers not in OUTLIER_POLICIES:
            raise InputError(f"outliers must be one of {', '.join(OUTLIER_POLICIES)}, "
                             f"not {self.outliers!r}")
        if not 1.5 <= self.outlier_ratio <= 20:
            raise InputError(f"outlier ratio {self.outlier_ratio} is outside [1.5, 20]")
        return self

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def coerce(cls, settings) -> "ReconstructSettings":
        """Validated settings from None (the defaults), a ReconstructSettings or a dict of
        settings (``{"resolution": 128}``); anything else is an InputError."""
        if settings is None:
            return cls().validate()
        if isinstance(settings, cls):
            return settings.validate()
        if isinstance(settings, Mapping):
            return cls.from_dict(dict(settings))
        raise InputError(f"settings must be a ReconstructSettings or a dict of settings, not "
                         f"{type(settings).__name__}")

    @classmethod
    def from_dict(cls, values: dict) -> "ReconstructSettings":
        if not isinstance(values, Mapping):
            raise InputError(f"settings must be a dict, not {type(values).__name__}")
        if any(not isinstance(key, str) for key in values):
            raise InputError("settings names must be strings")
        known = {f.name for f in fields(cls)}
        unknown = set(values) - known
        if unknown:
            raise InputError(f"unknown settings: {', '.join(sorted(unknown))}")
        return cls(**values).validate()


def _check_type(name: str, value, kind: type) -> None:
    """Refuse a setting of the wrong type: integers (Python or numpy) for int settings, never
    floats, which would be truncated silently; real finite numbers for float settings; strings
    for str settings. Booleans are never numbers here."""
    label = name.replace("_", " ")
    if kind is int:
        if isinstance(value, bool) or not isinstance(value, numbers.Integral):
            raise InputError(f"{label} must be a whole number, not {value!r} "
                             f"({type(value).__name__})")
    elif kind is float:
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise InputError(f"{label} must be a number, not {value!r} ({type(value).__name__})")
        if not math.isfinite(value):
            raise InputError(f"{label} must be a finite number, not {value!r}")
    elif kind is str and not isinstance(value, str):
        raise InputError(f"{label} must be a string, not {value!r} ({type(value).__name__})")
