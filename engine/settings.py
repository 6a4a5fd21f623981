"""Settings of one reconstruction: one dataclass shared by the CLI, Blender, batch and benchmark.

Each field says what it is in its metadata (:func:`setting`): the panel's label and tooltip, the
command line's help, the allowed range or choices. The command-line flags
(``engine/commands/settings_args.py``), the Blender panel's properties (``ui/properties.py``)
and :meth:`ReconstructSettings.validate` are all built from the fields, so a new field added
here appears everywhere with no other edit.
"""

import math
import numbers
import struct
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from typing import Optional, Tuple

from .errors import InputError

MAX_SEED = 2 ** 32 - 1
"""Seeds are whole numbers in [0, MAX_SEED] (what numpy's generators accept)."""


@dataclass(frozen=True)
class Choice:
    """One allowed value of a setting, with the panel's name and tooltip for it."""

    value: str
    label: str
    description: str


@dataclass(frozen=True)
class SettingInfo:
    """What the CLI, the panel and validation know about one setting.

    label, description: the panel's name and tooltip, in an artist's words.
    help: the command line's help (the tooltip when empty); the default is appended.
    choices: the allowed values (an enum in the panel, ``choices`` on the command line).
    low, high: the allowed range, inclusive (None: unbounded).
    ui: extra keywords of the Blender property (soft limits, step, precision, subtype).
    implies: ``(setting, value)`` that giving this setting's command-line flag also sets,
        unless that setting was given a value of its own (``--voxel-size`` sets ``detail``).
    """

    label: str
    description: str = ""
    help: str = ""
    choices: Tuple[Choice, ...] = ()
    low: Optional[float] = None
    high: Optional[float] = None
    ui: Tuple[Tuple[str, object], ...] = ()
    implies: Tuple[Tuple[str, object], ...] = ()

    @property
    def cli_help(self) -> str:
        return self.help or self.description

    @property
    def values(self) -> tuple:
        return tuple(choice.value for choice in self.choices)


def setting(default, label: str, description: str, *, help: str = "", choices=(), low=None,
            high=None, implies=(), **ui):
    """A field of :class:`ReconstructSettings` with its :class:`SettingInfo`; extra keywords
    go to the Blender property as they are (``soft_max=0.06``, ``precision=3``)."""
    info = SettingInfo(label, description, help, tuple(choices), low, high,
                       tuple(sorted(ui.items())), tuple(implies))
    return field(default=default, metadata={"setting": info})


def setting_info(item) -> SettingInfo:
    """The :class:`SettingInfo` of a dataclass field; a field declared without :func:`setting`
    gets its name as label and nothing else."""
    info = item.metadata.get("setting")
    return info if info is not None else SettingInfo(item.name.replace("_", " ").title())


RADIUS_MODE_CHOICES = (
    Choice("fixed", "Fixed",
           "One ball radius everywhere. Fast and predictable; thin parts and fine detail may "
           "blur when the radius is large"),
    Choice("curvature", "Curvature",
           "Smaller balls where the surface bends, larger ones where it is flat"),
    Choice("learned", "Learned",
           "A small network picks the ball size for each spot from the points around it: "
           "smaller where the scan looks clean, larger where it looks noisy or sparse"),
)
DEVICE_CHOICES = (
    Choice("auto", "Auto", "Use the graphics card when PyTorch with CUDA is installed, else the "
                           "CPU"),
    Choice("cpu", "CPU", "Always compute on the processor"),
    Choice("cuda", "CUDA", "Compute on an NVIDIA graphics card (needs PyTorch with CUDA and a "
                           "GPU)"),
)
OUTLIER_CHOICES = (
    Choice("auto", "Auto", "Drop stray points when they are at least 1 % of the cloud or when "
                           "they more than double its size; keep a cleaner cloud as it is"),
    Choice("drop", "Drop", "Always drop points isolated from the surface"),
    Choice("keep", "Keep", "Use every point"),
)
DETAIL_CHOICES = (
    Choice("auto", "Auto", "Resolution cells along the cloud's longest side for up to 50,000 "
                           "points; finer cells for denser clouds, so each cell holds about "
                           "as many points"),
    Choice("resolution", "Resolution", "Exactly Resolution cells along the cloud's longest "
                                       "side"),
    Choice("voxel_size", "Voxel Size", "Cells of a set length in the cloud's own units"),
)
UDF_SOURCE_CHOICES = (
    Choice("network", "Network", "The learned network judges the distance to the surface"),
    Choice("nearest", "Nearest Point", "The distance to the nearest point, without the network "
                                       "(a baseline: rougher on noisy scans)"),
)

RADIUS_MODES = tuple(choice.value for choice in RADIUS_MODE_CHOICES)
MODE_RANGES = {
    "curvature": (0.024, 0.5, 1.0),
    # the shipped selector's training range (engine/weights/selector.json): 0.015 to 0.072
    "learned": (0.072, 0.015 / 0.072, 1.0),
}
"""(R, rho_min, rho_max) of the per-query radius modes unless ``custom_range`` is set: the
selector's is the range it was trained for; the curvature heuristic's stops at 0.024, past which
clean scans lose accuracy (engine/weights/SELECTOR_CARD.md)."""


def radius_range(settings) -> Tuple[float, float, float]:
    """(R, rho_min, rho_max) the radius policy of ``settings`` works in (unit frame): the mode's
    own range, or the settings' when ``custom_range`` is set. Anything with those attributes
    will do (the panel passes its properties)."""
    if settings.custom_range or settings.radius_mode not in MODE_RANGES:
        return float(settings.parent_radius), float(settings.rho_min), float(settings.rho_max)
    return MODE_RANGES[settings.radius_mode]
DEVICES = tuple(choice.value for choice in DEVICE_CHOICES)
"""The device settings of the reconstruction and of the mesher."""
OUTLIER_POLICIES = tuple(choice.value for choice in OUTLIER_CHOICES)
"""What reconstruction does with the outliers found (:mod:`.outliers`): ``drop`` them, ``keep``
them, or ``auto``: drop them when they are at least ``AUTO_SHARE`` of the cloud or when they
stretch the bounding box (``AUTO_SHRINK``), else keep them."""
UDF_SOURCES = tuple(choice.value for choice in UDF_SOURCE_CHOICES)

MIN_TILE_CELLS = 24
"""Smallest tile side (cells): a tile's halo and the widest ball must stay a minor part of it."""

DEFAULT_OUTLIER_RATIO = 2.5
"""Spacing over context median above which a point is an outlier (:mod:`.outliers`)."""


@dataclass
class ReconstructSettings:
    """How to reconstruct. Radii are lengths in the working frame, where a grid cell is
    ``1 / resolution`` (:mod:`engine.detail`): the unit frame (bounding box longest side 1) unless
    ``detail`` makes the cells finer; ``voxel_size`` is in the input's units.

    Each field's metadata says what it means (:func:`setting_info`).
    """

    radius_mode: str = setting(
        "learned", "Radius Mode",
        "How big a neighbourhood of points is used to judge the distance to the surface at "
        "each spot",
        help="how the backbone's ball radius is chosen per query: fixed (one radius, as "
             "LoSF-UDF), curvature (smaller where the surface bends) or learned (the selector "
             "network predicts it)",
        choices=RADIUS_MODE_CHOICES)
    radius: float = setting(
        0.018, "Radius",
        "Neighbourhood size, as a fraction of Resolution cells (the cloud's longest side unless "
        "Detail makes the cells finer). Larger fills holes and smooths noise; smaller keeps "
        "thin parts and detail",
        help="ball radius of the fixed mode, working frame",
        low=0.001, high=0.2, soft_min=0.005, soft_max=0.06, step=0.1, precision=3)
    custom_range: bool = setting(
        False, "Custom Range",
        "Set the radius range yourself. Off: each mode uses its own tuned range (Curvature "
        "0.012 to 0.024, Learned 0.015 to 0.072)",
        help="use --parent-radius, --rho-min and --rho-max instead of the radius mode's own "
             "range (curvature: R 0.024, rho 0.5 to 1; learned: the range its selector was "
             "trained for, R 0.072, rho 0.208 to 1); giving any of those flags sets it")
    parent_radius: float = setting(
        0.024, "Largest Radius",
        "The biggest neighbourhood any spot may use, as a fraction of Resolution cells (the "
        "cloud's longest side unless Detail makes the cells finer). Each spot gets a radius "
        "between Range Min and Max times this. Larger fills holes and smooths noise; smaller "
        "keeps thin parts and detail",
        help="parent ball radius R of the curvature and learned modes, working frame (with "
             "--custom-range)",
        implies=(("custom_range", True),),
        low=0.001, high=0.2, soft_min=0.005, soft_max=0.1, step=0.1, precision=3)
    rho_min: float = setting(
        0.5, "Min", "Smallest radius a spot may get, as a share of the Largest Radius",
        help="smallest radius as a fraction of R (with --custom-range)",
        implies=(("custom_range", True),),
        low=0.05, high=1, step=1, precision=2, subtype="FACTOR")
    rho_max: float = setting(
        1.0, "Max", "Biggest radius a spot may get, as a share of the Largest Radius",
        help="largest radius as a fraction of R (with --custom-range)",
        implies=(("custom_range", True),),
        low=0.05, high=1, step=1, precision=2, subtype="FACTOR")
    resolution: int = setting(
        256, "Resolution",
        "Grid cells along the cloud's longest side. Higher keeps finer detail but takes longer "
        "and uses more memory (about 8x per doubling)",
        help="grid cells along the longest side of the bounding box (with --detail auto: "
             "for clouds of up to 50,000 points, finer for denser ones)",
        low=32, high=1024, soft_min=64, soft_max=512)
    detail: str = setting(
        "auto", "Detail", "How the size of the grid cells is chosen",
        help="how the grid's cell size is chosen: auto (Resolution cells along the longest "
             "side, finer for clouds denser than 50,000 points), resolution (exactly "
             "Resolution cells) or voxel_size (cells of --voxel-size in the input's units); "
             "ball radii are measured in Resolution cells, so they follow the cells",
        choices=DETAIL_CHOICES)
    voxel_size: float = setting(
        0.01, "Voxel Size",
        "Length of a grid cell in the cloud's own units, when Detail is Voxel Size. Smaller "
        "keeps finer detail but takes longer and uses more memory",
        help="cell length in the input's units; giving it sets --detail voxel_size",
        implies=(("detail", "voxel_size"),), low=1e-9, high=1e9, soft_min=0.0001,
        soft_max=10.0, precision=4, subtype="DISTANCE")
    tile_cells: int = setting(
        0, "Tile Size",
        "Cells per side of the tiles a large grid is made in (0: tiles of 192 cells when the "
        "grid is larger than 512 cells). Memory follows the tile size, not the scan",
        help="cells per side of a tile; 0: tiles of 192 cells when the grid has more than 512 "
             "cells along its longest side, else one grid",
        low=0, high=4096, soft_max=1024)
    workers: int = setting(
        0, "Workers",
        "CPU cores to use: processes that make tiles side by side, or threads for a scan made "
        "in one grid (0: every core). The mesh is the same for any number",
        help="CPU cores to use: worker processes for the tiles, or threads for a scan made in "
             "one grid (1: one core throughout); 0: every core; the mesh is the same, bit for "
             "bit, for any number",
        low=0, high=1024, soft_max=64)
    scheduler: str = setting(
        "", "Dask Scheduler",
        "Run the tiles on a Dask cluster: 'local' for one on this computer, or a scheduler's "
        "address (needs Dask)",
        help="run the tiles on Dask: 'local' starts a local cluster of --workers processes, "
             "else a scheduler address such as tcp://host:8786 (needs pip install "
             "\"dask[distributed]\"); empty: no Dask")
    device: str = setting(
        "auto", "Device", "Where the neural network runs",
        help="where the networks run: auto (CUDA when PyTorch sees a GPU), cpu or cuda",
        choices=DEVICE_CHOICES)
    seed: int = setting(
        0, "Seed", "Same cloud, same settings and same seed give the same mesh",
        help=f"seed of the random choices, 0 to {MAX_SEED}; every stage is deterministic, "
             f"so the mesh is the same for every seed",
        low=0, high=MAX_SEED)
    min_component_faces: int = setting(
        0, "Min Piece Faces",
        "Delete loose pieces of the result with fewer faces than this (0 keeps every piece)",
        help="drop output pieces with fewer faces (0 keeps all)",
        low=0, soft_max=10000)
    outliers: str = setting(
        "auto", "Outliers", "What to do with stray points floating off the surface",
        help="points isolated from the surface: drop them, keep them, or auto: drop them when "
             "they are at least 1 % of the cloud or stretch its bounding box more than 2x",
        choices=OUTLIER_CHOICES)
    outlier_ratio: float = setting(
        DEFAULT_OUTLIER_RATIO, "Outlier Ratio",
        "A point is stray when its gap to its neighbours is more than this many times that of "
        "the points around it (lower finds more)",
        help="a point is isolated when its gap to its neighbours is more than this many times "
             "that of the points around it (lower finds more)",
        low=1.5, high=20, step=10, precision=1)
    fill_gaps: bool = setting(
        True, "Fill Gaps",
        "Carry flat surfaces across gaps between the points of a sparse scan that are wider "
        "than the ball radius (rims, where the points lie on one side only, stay open; a hole "
        "in a flat surface narrower than about 24 grid cells is closed too)",
        help="carry flat surfaces across the gaps of a sparse scan wider than the ball radius; "
             "open rims stay open, holes in a flat surface narrower than about 24 grid cells "
             "close (--no-fill-gaps keeps them)")
    udf_source: str = setting(
        "network", "Distances",
        "Where the distances to the surface come from: the network, or the nearest point (a "
        "baseline without the network)",
        help="the learned backbone, or the distance to the nearest input point (a non-learned "
             "baseline)",
        choices=UDF_SOURCE_CHOICES)

    def validate(self) -> "ReconstructSettings":
        """Raise :class:`InputError` with a clear message when a setting is out of range or of
        the wrong type (a string resolution, a float or negative seed, ...)."""
        for item in fields(self):
            _check_value(item.name, getattr(self, item.name), type(item.default),
                         setting_info(item))
        if 0 < self.tile_cells < MIN_TILE_CELLS:
            raise InputError(f"tile cells must be 0 (automatic) or at least {MIN_TILE_CELLS}, "
                             f"not {self.tile_cells}")
        if self.rho_min > self.rho_max:
            raise InputError(f"need rho_min <= rho_max, got rho_min={self.rho_min}, "
                             f"rho_max={self.rho_max}")
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

    @classmethod
    def from_attributes(cls, source, single_precision: bool = False) -> "ReconstructSettings":
        """Validated settings read from the same-named attributes of ``source`` (an argparse
        namespace, a Blender property group).

        single_precision: the floats were stored in single precision (Blender's float
        properties); each is read back as the shortest decimal that rounds to it, so 0.018
        reaches the engine as 0.018, not 0.017999999225139618.
        """
        values = {item.name: getattr(source, item.name) for item in fields(cls)}
        if single_precision:
            values = {name: _shortest_single(value) if type(value) is float else value
                      for name, value in values.items()}
        return cls.from_dict(values)


def _shortest_single(value: float) -> float:
    """The decimal with the fewest digits whose single-precision value is ``value``'s."""
    if not math.isfinite(value):
        return value
    single = struct.pack("<f", value)
    for digits in range(1, 10):
        candidate = float(f"{value:.{digits}g}")
        if struct.pack("<f", candidate) == single:
            return candidate
    return value


def _check_value(name: str, value, kind: type, info: SettingInfo) -> None:
    """Refuse a setting of the wrong type, outside its choices or outside its range.

    Integers (Python or numpy) for int settings, never floats, which would be truncated
    without a word; real finite numbers for float settings; strings for str settings. Booleans are
    never numbers here.
    """
    label = name.replace("_", " ")
    if kind is bool:
        if not isinstance(value, bool):
            raise InputError(f"{label} must be True or False, not {value!r}")
    elif kind is int:
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
    if info.choices and value not in info.values:
        raise InputError(f"{label} must be one of {', '.join(info.values)}, not {value!r}")
    if info.low is not None and info.high is not None:
        if not info.low <= value <= info.high:
            raise InputError(f"{label} {value} is outside [{info.low}, {info.high}]")
    elif info.low is not None and value < info.low:
        raise InputError(f"{label} must be >= {info.low}, not {value}")
    elif info.high is not None and value > info.high:
        raise InputError(f"{label} must be <= {info.high}, not {value}")
