"""The unit frame: the points' bounding box centred at the origin, longest side 1.

Every radius, grid spacing and metric threshold of the engine is measured in this frame, so a
reconstruction behaves the same whatever the input's units. The frame also refuses clouds no
surface can be built from, with a message that says what to do.
"""

from dataclasses import dataclass

import numpy as np

from .errors import InputError

MIN_POINTS = 10
"""Fewest distinct points accepted; fewer cannot describe a surface."""

_LINE_TOLERANCE = 1e-9
"""A cloud is a line when every point lies within this fraction of its extent from one line
(or within :data:`_ROUNDING_ULPS` roundings of its coordinates, when that is more)."""

_ROUNDING_ULPS = 8.0
"""Float64 roundings (``eps * largest |coordinate|``) within which a point is on the line: far
from the origin (offset 1e8, extent 16) the coordinates' own rounding moves collinear points
off their line by more than :data:`_LINE_TOLERANCE` of the extent (1.7e-9 measured)."""

SMALLEST_EXTENT = 1e-100
"""Smallest extent (bounding box's longest side, input units) accepted: squared distances
between neighbours of a smaller cloud underflow."""

LARGEST_COORDINATE = 1e100
"""Largest absolute coordinate (input units) accepted: squared distances overflow beyond."""

_UNIQUE_SAMPLE = 4096
"""Distinct points are first counted in this many leading points; usually that settles it."""

_LINE_CHUNK = 1 << 20
"""Points per chunk of the line test (:func:`_on_a_line`)."""


@dataclass(frozen=True, eq=False)
class UnitFrame:
    """A similarity transform from input units to the unit frame: ``unit = (x - center) / scale``.

    Attributes
    ----------
    center : (3,) float64, read-only
        The centre of the points' axis-aligned bounding box, in input units.
    scale : float
        The bounding box's longest side, in input units (> 0).
    """

    center: np.ndarray
    scale: float

    def __post_init__(self):
        center = np.array(self.center, dtype=np.float64).reshape(3)
        center.setflags(write=False)
        object.__setattr__(self, "center", center)
        object.__setattr__(self, "scale", float(self.scale))
        if not (np.isfinite(self.scale) and self.scale > 0 and np.isfinite(center).all()):
            raise InputError(f"a unit frame needs a finite centre and a positive scale, got "
                             f"centre {center.tolist()} and scale {self.scale}")

    @classmethod
    def from_points(cls, points, min_points: int = MIN_POINTS) -> "UnitFrame":
        """The frame of a cloud, after :func:`validate_points` accepts it.

        Parameters
        ----------
        points : (N, 3) array-like of numbers, input units
        min_points : fewest distinct points accepted

        Returns
        -------
        UnitFrame
            centre = bounding-box centre, scale = bounding box's longest side.
        """
        points = validate_points(points, min_points)
        low, high = points.min(axis=0), points.max(axis=0)
        return cls(center=(low + high) / 2.0, scale=float(np.max(high - low)))

    def to_unit(self, x) -> np.ndarray:
        """Input units -> unit frame: ``(x - center) / scale``; x: (..., 3) -> (..., 3) float64."""
        return (np.asarray(x, dtype=np.float64) - self.center) / self.scale

    def from_unit(self, x, in_place: bool = False) -> np.ndarray:
        """Unit frame -> input units: ``x * scale + center``, the inverse of :meth:`to_unit`
        to float64 rounding; x: (..., 3) -> (..., 3) float64. ``in_place``: overwrite ``x``
        (a float64 array) instead of making a new array; the same values."""
        if not in_place:
            return np.asarray(x, dtype=np.float64) * self.scale + self.center
        x *= self.scale
        x += self.center
        return x


def validate_points(points, min_points: int = MIN_POINTS) -> np.ndarray:
    """Check that a surface can be reconstructed from a cloud; refuse it with a clear message.

    Refused: anything that is not an (N, 3) array of numbers; NaN or infinite coordinates;
    fewer than ``min_points`` points, or fewer than ``min_points`` distinct ones (duplicates
    are allowed otherwise); all points at one position; absurd scales (an extent under
    :data:`SMALLEST_EXTENT` or a coordinate over :data:`LARGEST_COORDINATE`); all points on
    one line (tested in the centred frame scaled to extent 1, so the same line is refused
    wherever it lies).

    Parameters
    ----------
    points : (N, 3) array-like of numbers, any units
    min_points : fewest distinct points accepted (default :data:`MIN_POINTS`)

    Returns
    -------
    (N, 3) float64
        The same points as a float64 array (not a copy when already one).

    Raises
    ------
    InputError
        Saying what is wrong and what to do.
    """
    try:
        array = np.asarray(points)
    except (ValueError, TypeError):
        array = None
    if array is None or array.dtype.kind not in "iuf":
        raise InputError("the points must be an (N, 3) array of numbers; got "
                         f"{type(points).__name__}" + ("" if array is None else
                                                       f" of {array.dtype}"))
    if array.ndim != 2 or array.shape[1] != 3:
        raise InputError(f"the points must be an (N, 3) array (x, y, z per row); got shape "
                         f"{array.shape}")
    array = array.astype(np.float64, copy=False)
    count = len(array)
    if count == 0:
        raise InputError("the point cloud is empty; choose an object or file that has points")
    if count < min_points:
        raise InputError(f"only {count} points; a surface needs at least {min_points}: "
                         f"add more points or choose a denser cloud")
    finite = np.isfinite(array).all(axis=1)
    if not finite.all():
        bad = count - int(finite.sum())
        raise InputError(f"{bad} of {count} points have NaN or infinite coordinates; remove "
                         f"them (or fix the export that wrote them) and try again")
    low, high = array.min(axis=0), array.max(axis=0)
    largest = float(max(np.max(np.abs(low)), np.max(np.abs(high))))
    if largest > LARGEST_COORDINATE:
        raise InputError(f"the coordinates reach {largest:.3g}; coordinates up to "
                         f"{LARGEST_COORDINATE:.0e} are accepted: rescale the cloud (or fix "
                         f"the export's units) and try again")
    extent = float(np.max(high - low))
    if extent == 0.0:
        raise InputError(f"all {count} points are at the same position {low.tolist()}; "
                         f"a surface needs points spread over an area")
    if extent < SMALLEST_EXTENT:
        raise InputError(f"the points span only {extent:.3g} units; an extent of at least "
                         f"{SMALLEST_EXTENT:.0e} is accepted: rescale the cloud (or fix the "
                         f"export's units) and try again")
    distinct = _count_distinct(array, min_points)
    if distinct < min_points:
        raise InputError(f"only {distinct} distinct points ({count} with duplicates); a "
                         f"surface needs at least {min_points}: add more points")
    if _on_a_line(array, (low + high) / 2.0, extent, largest):
        raise InputError("all points lie on a line; a surface needs a 2-D spread: check "
                         "that the right object or file was chosen")
    return array


def _count_distinct(points: np.ndarray, enough: int) -> int:
    """Number of distinct rows, or any number >= ``enough`` once that many are certain.

    Counting distinct rows of a large cloud means sorting it (seconds for millions); the
    distinct rows among a leading sample are a lower bound, which almost always settles it.
    """
    sample = points[:_UNIQUE_SAMPLE]
    distinct = len(np.unique(sample, axis=0))
    if distinct >= enough or len(sample) == len(points):
        return distinct
    return len(np.unique(points, axis=0))


def _on_a_line(points: np.ndarray, center: np.ndarray, extent: float, largest: float) -> bool:
    """True when every point lies within ``_LINE_TOLERANCE`` of one line, in the unit frame.

    The shape is tested on the points centred on their bounding box's ``center`` and scaled by
    its ``extent`` (the unit frame), so the test is the same at any offset and scale: no
    scatter matrix over- or underflows. The line tested is the least-squares one: through the
    centroid along the principal axis (the largest eigenvector of the 3 x 3 scatter matrix).
    Far from the origin the coordinates' rounding (``largest`` absolute coordinate) widens the
    tolerance (:data:`_ROUNDING_ULPS`).
    """
    starts = range(0, len(points), _LINE_CHUNK)  # a few copies of a chunk, not of the cloud

    def centred(start: int) -> np.ndarray:
        return (points[start:start + _LINE_CHUNK] - center) / extent

    mean = sum(centred(start).sum(axis=0) for start in starts) / len(points)
    scatter = np.zeros((3, 3))
    for start in starts:
        chunk = centred(start) - mean
        scatter += chunk.T @ chunk
    _, vectors = np.linalg.eigh(scatter)
    axis = vectors[:, -1]
    farthest = 0.0
    for start in starts:
        chunk = centred(start) - mean
        off_line = chunk - np.outer(chunk @ axis, axis)
        farthest = max(farthest, float(np.max(np.einsum("ij,ij->i", off_line, off_line))))
    tolerance = max(_LINE_TOLERANCE, _ROUNDING_ULPS * np.finfo(np.float64).eps * largest / extent)
    return float(np.sqrt(farthest)) <= tolerance
