"""How fine the grid is: the cell length in the input's units, and the frame the engine works in.

Three ways to set it (``ReconstructSettings.detail``):

- ``resolution``: ``resolution`` cells along the cloud's longest side;
- ``voxel_size``: cells of ``voxel_size`` in the input's units, whatever the cloud's size;
- ``auto``: ``resolution`` cells along the longest side for clouds of up to
  :data:`AUTO_POINTS` points; denser clouds get cells shrunk by ``sqrt(points / AUTO_POINTS)``,
  so each cell holds about as many points as in a 50,000-point cloud. A scan of a room with a
  million points gets about 4.5 times finer cells than the same room with 50,000.

The engine works in a frame centred on the bounding box and scaled so that one cell is
``1 / resolution``: the *working frame*. Every ball radius is a length in that frame, that is
a number of cells times ``1 / resolution`` (the default radius 0.018 at resolution 256 is 4.6
cells): with ``detail=resolution`` the working frame is the unit frame (longest side 1), as
the radii have always been read; with finer cells the balls shrink with the cells, so a large
scene gets the same detail per square metre as a small object.
"""

import math
from dataclasses import dataclass

import numpy as np

from .errors import InputError
from .frame import UnitFrame
from .settings import ReconstructSettings

AUTO_POINTS = 50_000
"""Up to this many points, ``auto`` is ``resolution`` cells along the longest side."""
AUTO_MAX_CELLS = 512
"""``auto`` never makes more cells than this along the longest side (memory grows with the
surface area in cells); a finer grid needs an explicit voxel size."""
MAX_CELLS = 2048
"""Most cells along the longest side of one grid: a scan made without tiles, or one tile."""
MAX_TILED_CELLS = 262_144
"""Most cells along the longest side of a scan made in tiles (2.6 km at 1 cm): a worker's memory
follows the tile, not the scan, and the main process holds the mesh."""


@dataclass(frozen=True)
class Detail:
    """The grid a reconstruction uses.

    voxel_size : cell length, input units
    cells : cells along the bounding box's longest side
    frame : the working frame (cell = 1 / resolution)
    capped : ``auto`` wanted finer cells than :data:`AUTO_MAX_CELLS` allows
    """

    voxel_size: float
    cells: float
    frame: UnitFrame
    capped: bool = False


def choose_detail(points: np.ndarray, settings: ReconstructSettings) -> Detail:
    """The cell length and working frame of a validated cloud (input units) and its settings.

    Raises
    ------
    InputError
        A voxel size that gives more than :data:`MAX_TILED_CELLS` cells along the longest side,
        or more than :data:`MAX_CELLS` in one grid (tiles asked larger than that).
    """
    low, high = points.min(axis=0), points.max(axis=0)
    extent = float(np.max(high - low))
    voxel, cells, capped = cell_size(len(points), extent, settings)
    if cells > MAX_TILED_CELLS:
        raise InputError(
            f"a voxel size of {voxel:.4g} makes {cells:,.0f} cells along the cloud's longest "
            f"side ({extent:.4g} units); at most {MAX_TILED_CELLS:,} are possible: raise the "
            f"voxel size to at least {_round_up(extent / MAX_TILED_CELLS)}")
    if cells > MAX_CELLS and settings.tile_cells > MAX_CELLS:
        raise InputError(
            f"tiles of {settings.tile_cells:,} cells are larger than one grid may be "
            f"({MAX_CELLS:,} cells per side); set tile cells to at most {MAX_CELLS:,}, or 0 for "
            f"automatic tiles")
    # the ratio is exactly 1 when the cells are the resolution: the unit frame, bit for bit
    scale = extent * (settings.resolution / cells)
    return Detail(voxel, cells, UnitFrame(center=(low + high) / 2.0, scale=scale), capped)


def cell_size(count: int, extent: float, settings: ReconstructSettings):
    """``(voxel size in input units, cells along the longest side, capped)`` for a cloud of
    ``count`` points whose bounding box's longest side is ``extent``; the panel shows it."""
    if settings.detail == "voxel_size":
        return float(settings.voxel_size), extent / settings.voxel_size, False
    cells = float(settings.resolution)
    capped = False
    if settings.detail == "auto":
        cells *= math.sqrt(max(count, AUTO_POINTS) / AUTO_POINTS)
        most = float(max(AUTO_MAX_CELLS, settings.resolution))
        if cells > most:
            cells, capped = most, True
    return extent / cells, cells, capped


def _round_up(value: float) -> str:
    """``value`` rounded up to 3 significant digits, as text."""
    digits = 2 - math.floor(math.log10(value))
    return f"{math.ceil(value * 10 ** digits) / 10 ** digits:.{max(digits, 0)}f}"
