"""Which tiles a cloud needs, and which points each tile reads (:mod:`.tiles`).

The tiles are cubes of ``tile_cells`` cells of the working frame's grid, from the cloud's lowest
corner; only those whose core holds a point are made. A tile reads the points within ``reach``
of its core. Scanning the whole cloud for each tile would cost the number of tiles times the
points; instead the points are sorted once by the core they lie in (:class:`CloudTiles`), and a
tile's points are gathered from its own core and the neighbouring cores within reach. Kept
across the tiles: the cloud as given (in the input's units when a frame maps it, so that no
copy of it in the working frame is held) and one index per point.
"""

import math
from dataclasses import dataclass
from typing import Callable, Optional, Tuple

import numpy as np

_CHUNK = 1 << 20
"""Points mapped to the working frame at once while they are sorted into cores."""


@dataclass(frozen=True)
class Tile:
    """A cube of the grid: ``low <= x < high`` (working frame), numbered ``index`` per axis."""

    index: Tuple[int, int, int]
    low: np.ndarray
    high: np.ndarray


class CloudTiles:
    """A cloud's tiles (:attr:`tiles`) and each tile's points (:meth:`points_of`).

    The tiles are those of ``tile_cells`` cells per side that hold at least one point, in C
    order of their indices. The outermost tiles reach to infinity on their outer sides, so
    every point is in exactly one core.

    Parameters
    ----------
    points : (N, 3) float64, the cloud (held, not copied)
    spacing : the grid's cell size, working frame
    tile_cells : cells per tile side
    reach : how far beyond its core a tile reads points, working frame
    to_unit : maps ``points`` to the working frame (elementwise, order-preserving per axis, as
        :meth:`.frame.UnitFrame.to_unit`); None when they are in it
    """

    def __init__(self, points: np.ndarray, spacing: float, tile_cells: int, reach: float,
                 to_unit: Optional[Callable[[np.ndarray], np.ndarray]] = None):
        self.points = points
        self.to_unit = to_unit or (lambda x: np.asarray(x, np.float64))
        self.reach = reach
        # an order-preserving map: the extremes of the mapped points are the mapped extremes
        self.low = self.to_unit(points.min(axis=0))
        self.high = self.to_unit(points.max(axis=0))
        size = tile_cells * spacing
        counts = np.maximum(np.ceil((self.high - self.low) / size - 1e-9).astype(np.int64), 1)
        keys = np.empty(len(points), np.int64)
        for start in range(0, len(points), _CHUNK):
            unit = self.to_unit(points[start:start + _CHUNK])
            which = np.minimum(np.floor((unit - self.low) / size).astype(np.int64), counts - 1)
            keys[start:start + _CHUNK] = np.ravel_multi_index(which.T, counts)
        index_type = np.int32 if len(points) < 2 ** 31 else np.int64
        self._order = np.argsort(keys, kind="stable").astype(index_type)  # by core
        per_core = np.bincount(keys, minlength=int(np.prod(counts)))
        del keys
        self._starts = np.concatenate([[0], np.cumsum(per_core)])
        self._counts = counts
        self._span = int(math.floor(reach / size)) + 1  # the cores a point within reach is in
        self.tiles = []
        for flat in np.flatnonzero(per_core):
            index = np.array(np.unravel_index(flat, counts))
            tile_low = np.where(index == 0, -np.inf, self.low + index * size)
            tile_high = np.where(index == counts - 1, np.inf, self.low + (index + 1) * size)
            self.tiles.append(Tile(tuple(int(i) for i in index), tile_low, tile_high))

    def _cores_near(self, number: int) -> np.ndarray:
        """The cores within reach of tile ``number``'s core (flat indices)."""
        ranges = [range(max(i - self._span, 0), min(i + self._span, n - 1) + 1)
                  for i, n in zip(self.tiles[number].index, self._counts)]
        return np.ravel_multi_index(np.meshgrid(*ranges, indexing="ij"), self._counts).ravel()

    def cost_of(self, number: int) -> int:
        """The points in the cores tile ``number`` reads from: at least its points, and what
        gathering them costs."""
        cores = self._cores_near(number)
        return int((self._starts[cores + 1] - self._starts[cores]).sum())

    def points_of(self, number: int) -> np.ndarray:
        """The points (working frame) within ``reach`` of tile ``number``'s core, per axis, in
        the cloud's order."""
        tile = self.tiles[number]
        candidates = np.sort(np.concatenate(
            [self._order[self._starts[core]:self._starts[core + 1]]
             for core in self._cores_near(number)]))
        unit = self.to_unit(self.points[candidates])
        inside = np.all((unit >= tile.low - self.reach) & (unit < tile.high + self.reach),
                        axis=1)
        return unit[inside]
