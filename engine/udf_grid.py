"""Unsigned distance fields on a regular grid, queried as closest-point vectors.

The mesher never minimises a trilinearly interpolated distance: a multilinear function takes its
minima at grid nodes, which pulls vertices onto node layers instead of onto the surface. It uses
the closest-point field ``V = 1/2 grad(d^2) = p - closest(p)`` instead: ``d^2`` is differentiated
by central differences at the nodes and ``V`` is interpolated trilinearly. ``V`` reproduces a
plane exactly wherever it lies between the nodes, and ``|V|`` is the distance.

``V`` is only stored in 4^3-cell bricks near the surface (where some node has ``d < band``), so
memory follows the surface area, not the grid volume: the grid can come dense or as a sparse
band (what a network evaluates near the points).

Index and world coordinates: node ``(i, j, k)`` sits at ``origin + (i, j, k) * spacing``.
"""

from typing import Callable, Optional, Tuple

import numpy as np

from .compiled import kernels as load_kernels
from .errors import InputError

BRICK = 4  # cells per brick side
_NODES = BRICK + 1
_CELLS = BRICK ** 3

ExactFn = Callable[[np.ndarray], Tuple[np.ndarray, np.ndarray]]


class UDFGrid:
    """An unsigned distance field sampled on a regular, isotropic grid.

    Parameters
    ----------
    udf : (nx, ny, nz) float array
        Distances at the grid nodes, world units, non-negative.
    origin : (3,) float
        World position of node ``udf[0, 0, 0]``.
    spacing : float
        Distance between neighbouring nodes (world units, > 0).
    exact : callable, optional
        ``exact(points (P, 3)) -> (distances (P,), closest points (P, 3))``, world units. When
        given, the optimisation queries it instead of interpolating the grid (analytic shapes).
    far_value : float, optional
        A safe upper bound returned far from the surface; defaults to the grid maximum.
    """

    def __init__(self, udf, origin, spacing, exact: Optional[ExactFn] = None,
                 far_value: Optional[float] = None):
        udf = np.asarray(udf)
        if udf.ndim != 3 or min(udf.shape) < 2:
            raise InputError(f"the UDF grid must be 3-D with at least 2 nodes per axis, "
                             f"got shape {udf.shape}")
        udf = np.ascontiguousarray(udf, dtype=np.float32)
        if not np.all(np.isfinite(udf)):
            raise InputError("the UDF grid contains NaN or infinite values")
        self._dense = udf
        self._band = None
        self.shape = tuple(int(n) for n in udf.shape)
        self._init_common(origin, spacing, exact,
                          float(udf.max()) if far_value is None else float(far_value))
        self.min_value = float(udf.min())

    @classmethod
    def from_band(cls, indices, values, shape, origin, spacing, far_value,
                  exact: Optional[ExactFn] = None) -> "UDFGrid":
        """A grid known only on a sparse band of nodes; every other node holds ``far_value``.

        Parameters
        ----------
        indices : (M, 3) int
            Node indices of the band (unique, inside ``shape``).
        values : (M,) float
            Distances at those nodes, world units.
        shape : (3,) int
            Grid nodes per axis ``(nx, ny, nz)``.
        origin, spacing, exact : see :class:`UDFGrid`.
        far_value : float
            A safe upper bound of the distance outside the band (world units).
        """
        self = cls.__new__(cls)
        shape = tuple(int(n) for n in shape)
        if len(shape) != 3 or min(shape) < 2:
            raise InputError(f"the grid shape must be 3 integers >= 2, got {shape}")
        indices = np.asarray(indices)
        values = np.asarray(values, dtype=np.float32).reshape(-1)
        if indices.ndim != 2 or indices.shape[1] != 3 or indices.shape[0] != values.shape[0]:
            raise InputError(f"band indices must be (M, 3) and values (M,), got "
                             f"{indices.shape} and {values.shape}")
        if not np.all(np.isfinite(values)) or not np.isfinite(far_value):
            raise InputError("the UDF band contains NaN or infinite values")
        indices = indices.astype(np.int64)
        if indices.size and (indices.min() < 0 or np.any(indices.max(axis=0) >= shape)):
            raise InputError("band indices fall outside the grid shape")
        flat = np.ravel_multi_index(indices.T, shape)
        order = np.argsort(flat, kind="stable")
        flat = flat[order]
        if flat.size > 1 and np.any(flat[1:] == flat[:-1]):
            raise InputError("band indices contain duplicates")
        self._dense = None
        self._band = (flat, values[order])
        self.shape = shape
        self._init_common(origin, spacing, exact, float(far_value))
        self.min_value = float(min(values.min() if values.size else far_value, far_value))
        return self

    def _init_common(self, origin, spacing, exact, far_value):
        origin = np.asarray(origin, dtype=np.float64).reshape(-1)
        if origin.shape != (3,) or not np.all(np.isfinite(origin)):
            raise InputError(f"origin must be 3 finite numbers, got {origin}")
        spacing = float(np.asarray(spacing, dtype=np.float64).reshape(-1)[0]) \
            if np.size(spacing) == 1 else float("nan")
        if not np.isfinite(spacing) or spacing <= 0:
            raise InputError("spacing must be one positive number")
        self.origin = origin
        self.spacing = spacing
        self.exact = exact
        self.far_value = far_value
        self._bricks = None  # (table, field) once built

    # ----------------------------------------------------------------------------- coordinates
    def index_to_world(self, index: np.ndarray) -> np.ndarray:
        """Grid index coordinates (P, 3) → world positions (P, 3): ``origin + index * spacing``."""
        return self.origin + np.asarray(index, dtype=np.float64) * self.spacing

    def world_to_index(self, points: np.ndarray) -> np.ndarray:
        """World positions (P, 3) → grid index coordinates (P, 3), float64."""
        return (np.asarray(points, dtype=np.float64) - self.origin) / self.spacing

    # ----------------------------------------------------------------------------- node values
    def values_at(self, flat: np.ndarray) -> np.ndarray:
        """Distances (float32) at nodes given by flat C-order indices into ``shape``."""
        if self._dense is not None:
            return self._dense.reshape(-1)[flat]
        band_flat, band_values = self._band
        out = np.full(flat.shape, self.far_value, dtype=np.float32)
        if band_flat.size:
            pos = np.minimum(np.searchsorted(band_flat, flat), band_flat.size - 1)
            hit = band_flat[pos] == flat
            out[hit] = band_values[pos[hit]]
        return out

    def slab(self, x0: int, x1: int) -> np.ndarray:
        """Dense distances of the nodes ``x0 <= i < x1`` (all j, k), float32 (x1-x0, ny, nz)."""
        if self._dense is not None:
            return self._dense[x0:x1]
        nx, ny, nz = self.shape
        band_flat, band_values = self._band
        lo, hi = np.searchsorted(band_flat, [x0 * ny * nz, x1 * ny * nz])
        out = np.full((x1 - x0) * ny * nz, self.far_value, dtype=np.float32)
        out[band_flat[lo:hi] - x0 * ny * nz] = band_values[lo:hi]
        return out.reshape(x1 - x0, ny, nz)

    def band(self) -> Tuple[np.ndarray, np.ndarray]:
        """The nodes that hold a value of their own: index triples (M, 3) and distances (M,)
        (every node of a dense grid)."""
        if self._dense is not None:
            return np.argwhere(np.ones(self.shape, bool)), self._dense.reshape(-1).copy()
        band_flat, band_values = self._band
        return np.stack(np.unravel_index(band_flat, self.shape), axis=1), band_values.copy()

    def _small_nodes(self, limit: float) -> np.ndarray:
        """Index triples (M, 3) of the nodes with distance below ``limit``."""
        if self._dense is not None:
            return np.argwhere(self._dense < limit)
        band_flat, band_values = self._band
        return np.stack(np.unravel_index(band_flat[band_values < limit], self.shape), axis=1)

    # ----------------------------------------------------------------------------- V bricks
    def prepare(self, band: float) -> int:
        """Build V (voxel units) in the bricks that hold a node with ``d < band``.

        ``band`` is in world units; call it once before querying (``closest`` calls it with
        a default of 4 voxels when it was not called). Returns the number of bricks.
        """
        dims = np.array(self.shape)
        nbricks = (dims - 2) // BRICK + 1  # brick b covers cells 4b .. 4b+3 (cells 0 .. n-2)
        nodes = self._small_nodes(band)
        brick, first = nodes // BRICK, nodes % BRICK == 0
        marked = np.zeros(int(np.prod(nbricks)), bool)
        for shift in np.ndindex(2, 2, 2):  # node 4q is also the last node of brick q-1
            shift = np.array(shift)
            rows = np.all(first[:, shift == 1], axis=1)  # all rows for no shift
            b = brick[rows] - shift
            keep = np.all((b >= 0) & (b < nbricks), axis=1)
            marked[np.ravel_multi_index(b[keep].T, nbricks)] = True
        active = np.flatnonzero(marked)
        table = np.full(int(np.prod(nbricks)), -1, dtype=np.int32)
        table[active] = np.arange(active.size)
        corners = np.stack(np.unravel_index(active, nbricks), axis=1) * BRICK
        compiled = load_kernels("udf_grid_kernels")
        if compiled is None:
            cells = self._brick_coefficients(corners)
        else:
            dense = self._dense if self._dense is not None else np.zeros((0, 0, 0), np.float32)
            band_flat, band_values = self._band if self._band is not None else (
                np.zeros(0, np.int64), np.zeros(0, np.float32))
            cells = compiled.bricks(corners, dims.astype(np.int64), band_flat, band_values, dense,
                                    np.float32(self.far_value), float(self.spacing))
        self._bricks = (table, cells.reshape(-1, 3, 8), nbricks)
        return int(active.size)

    def _brick_coefficients(self, corners: np.ndarray) -> np.ndarray:
        """The trilinear coefficients (B + 1, BRICK, BRICK, BRICK, 3, 8) float32 of V in the
        bricks whose first nodes are ``corners`` (B, 3) (the last brick: zeros), in numpy."""
        dims = np.array(self.shape)
        field = np.zeros((len(corners) + 1, _NODES, _NODES, _NODES, 3), dtype=np.float32)
        # Gather (BRICK + 3)^3 nodes per brick (one-node halo for the central differences) in
        # chunks, compute V = 1/2 grad(d^2) on the inner nodes.
        local = np.arange(-1, _NODES + 1)
        for start in range(0, len(corners), 2048):
            base = corners[start:start + 2048]
            idx = [np.clip(base[:, a, None] + local[None, :], 0, dims[a] - 1) for a in range(3)]
            flat = ((idx[0][:, :, None, None] * dims[1] + idx[1][:, None, :, None]) * dims[2]
                    + idx[2][:, None, None, :])
            d2 = (self.values_at(flat).astype(np.float64) / self.spacing) ** 2  # voxels^2
            for a in range(3):
                sl_p = [slice(None), slice(1, -1), slice(1, -1), slice(1, -1)]
                sl_m = list(sl_p)
                sl_p[a + 1] = slice(2, None)
                sl_m[a + 1] = slice(0, -2)
                # true distance between the (clipped) neighbours, in voxels
                step = (idx[a][:, 2:] - idx[a][:, :-2]).astype(np.float64)
                shape = [-1, 1, 1, 1]
                shape[a + 1] = _NODES
                step = np.maximum(step, 1e-30).reshape(shape)
                field[start:start + base.shape[0], ..., a] = (
                    0.5 * (d2[tuple(sl_p)] - d2[tuple(sl_m)]) / step)
        # per cell, the 8 coefficients of the trilinear polynomial of each channel side by side
        # (one row gather per query): 1, tz, ty, ty tz, tx, tx tz, tx ty, tx ty tz
        cells = np.empty((len(corners) + 1, BRICK, BRICK, BRICK, 3, 8), dtype=np.float32)
        v = [field[:, dx:dx + BRICK, dy:dy + BRICK, dz:dz + BRICK]
             for dx, dy, dz in np.ndindex(2, 2, 2)]  # corner 4 dx + 2 dy + dz
        cells[..., 0] = v[0]
        cells[..., 1] = v[1] - v[0]
        cells[..., 2] = v[2] - v[0]
        cells[..., 3] = v[3] - v[2] - v[1] + v[0]
        cells[..., 4] = v[4] - v[0]
        cells[..., 5] = v[5] - v[4] - v[1] + v[0]
        cells[..., 6] = v[6] - v[4] - v[2] + v[0]
        cells[..., 7] = v[7] - v[6] - v[5] + v[4] - v[3] + v[2] + v[1] - v[0]
        del v
        return cells

    def brick_arrays(self) -> tuple:
        """The prepared bricks as plain arrays, for compiled lookups: the brick table (int32,
        -1 where no brick), the cells' trilinear coefficients (cells, 3, 8) float32 (see
        :meth:`_cell_coefficients`), the brick counts along y and z, the node counts per axis."""
        if self._bricks is None:
            self.prepare(4.0 * self.spacing + max(self.min_value, 0.0))
        table, coefficients, nbricks = self._bricks
        return (table, coefficients, int(nbricks[1]), int(nbricks[2])) + tuple(self.shape)

    def closest(self, points: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """Distance and closest-point vector at world positions.

        Parameters
        ----------
        points : (P, 3) float
            World positions.

        Returns
        -------
        distance : (P,) float64
            ``|V|``, world units; ``far_value`` outside the prepared band.
        vector : (P, 3) float64
            ``V = p - closest point`` (world units); zero outside the prepared band.
        """
        points = np.asarray(points, dtype=np.float64)
        if self.exact is not None:
            dist, cp = self.exact(points)
            return np.asarray(dist, np.float64), points - np.asarray(cp, np.float64)
        vec, inside = self._interpolate(self.world_to_index(points))
        vec *= self.spacing
        dist = np.sqrt(np.einsum("ij,ij->i", vec, vec))
        dist[~inside] = self.far_value
        return dist, vec

    def closest_index(self, index: np.ndarray, cells: Optional["CellCache"] = None
                      ) -> Tuple[np.ndarray, np.ndarray]:
        """Same as :meth:`closest` in grid index coordinates: lengths in voxels.

        Parameters
        ----------
        index : (P, 3) float64
            Grid index coordinates.
        cells : CellCache, optional
            The cells of an earlier query of as many points (the same points, moved): their
            interpolation coefficients are reused for the points still in the same cell. The
            result is the same as without it.

        Returns
        -------
        distance : (P,) float64 voxels, ``inf`` outside the band; vector : (P, 3) float64 voxels.
        """
        if self.exact is not None:
            dist, vec = self.closest(self.index_to_world(index))
            return dist / self.spacing, vec / self.spacing
        vec, inside = self._interpolate(np.asarray(index, dtype=np.float64), cells)
        dist = np.sqrt(np.einsum("ij,ij->i", vec, vec))
        dist[~inside] = np.inf
        return dist, vec

    def _interpolate(self, g: np.ndarray, cells: Optional["CellCache"] = None
                     ) -> Tuple[np.ndarray, np.ndarray]:
        """Trilinear V (voxel units, (P, 3) float64) at index coordinates, and an inside mask."""
        if self._bricks is None:
            self.prepare(4.0 * self.spacing + max(self.min_value, 0.0))
        # cell = floor(clip(g, 0, dims - 1)) capped at dims - 2, t = clip(g) - cell, computed as
        # clip(trunc(g)) and clip(g - cell, 0, 1) (the same numbers, fewer passes)
        cell = g.astype(np.int32)
        np.minimum(cell, np.array(self.shape, np.int32) - 2, out=cell)
        np.maximum(cell, 0, out=cell)
        t = (g - cell).astype(np.float32)
        np.clip(t, 0.0, 1.0, out=t)
        if cells is None:
            coef, inside = self._cell_coefficients(cell)
        else:
            coef, inside = cells.update(cell, self._cell_coefficients, self._bricks)
        tx, ty, tz = t.T
        terms = np.empty((len(g), 8), dtype=np.float32)
        terms[:, 0] = 1.0
        terms[:, 1] = tz
        terms[:, 2] = ty
        np.multiply(ty, tz, out=terms[:, 3])
        terms[:, 4] = tx
        np.multiply(tx, tz, out=terms[:, 5])
        np.multiply(tx, ty, out=terms[:, 6])
        np.multiply(terms[:, 6], tz, out=terms[:, 7])
        return np.einsum("nck,nk->nc", coef, terms).astype(np.float64), inside

    def _cell_coefficients(self, cell: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """The trilinear coefficients (P, 3, 8) float32 of V in cells (P, 3) int32 (zeros outside
        the prepared bricks) and the inside mask (P,) bool."""
        table, coefficients, nbricks = self._bricks
        brick = cell // BRICK
        local = cell - brick * BRICK  # the cell in its brick
        brick = (brick[:, 0] * int(nbricks[1]) + brick[:, 1]) * int(nbricks[2]) + brick[:, 2]
        slot = table[brick]
        inside = slot >= 0
        slot[~inside] = coefficients.shape[0] // _CELLS - 1  # last brick: zeros
        row = slot.astype(np.intp) * _CELLS
        row += (local[:, 0] * BRICK + local[:, 1]) * BRICK + local[:, 2]
        return np.take(coefficients, row, axis=0), inside


class CellCache:
    """The cells of the last query of a fixed set of moving points and their coefficients:
    points that stay in their cell skip the brick lookup and the coefficient gather.

    Its entries hold for the bricks they were read from: a query on another grid, or on the same
    grid prepared again, reads every point afresh.
    """

    def __init__(self):
        self.cell = self.coef = self.inside = self.bricks = None

    def update(self, cell: np.ndarray, coefficients, bricks
               ) -> Tuple[np.ndarray, np.ndarray]:
        """The coefficients and inside mask at ``cell`` (P, 3) int32; ``coefficients(cells)``
        computes them for the cells that changed; ``bricks``: the grid's prepared bricks."""
        if self.cell is None or len(self.cell) != len(cell) or self.bricks is not bricks:
            self.cell, self.bricks = cell, bricks
            self.coef, self.inside = coefficients(cell)
            return self.coef, self.inside
        changed = cell != self.cell
        moved = np.flatnonzero(changed[:, 0] | changed[:, 1] | changed[:, 2])
        if moved.size:
            self.cell[moved] = cell[moved]
            self.coef[moved], self.inside[moved] = coefficients(cell[moved])
        return self.coef, self.inside
