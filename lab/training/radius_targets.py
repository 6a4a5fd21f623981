"""Off-grid target radii for training the radius selector, from cached UDF-error curves.

For each training query the frozen backbone's absolute UDF error is measured at K candidate radii
(the paper: 0.012, 0.014, ..., 0.024 in the unit frame, evenly spaced; over a range that spans a
factor of several, :func:`candidate_radii` spaces them evenly in log r). The target r* is the
vertex of the parabola through the grid minimum and its two neighbours, in r or in log r as the
grid is spaced; at either end of the grid, or where the three points are not convex, r* falls
back to the grid minimum. Each query's loss is weighted by
how much the radius matters there, w = max(e) - min(e): a flat curve teaches nothing.

One departure from the paper, measured in engine/weights/SELECTOR_CARD.md: a query's error curve
is one draw of how the input points happen to fall, so its argmin is mostly noise (our backbone's
per-query best radius spreads over all seven). :func:`expected_errors` replaces each curve by the
mean curve of the nearest queries of the same shape, the *expected* error at that place, before
the parabola and the weight are taken. The loss is the paper's.
"""

import numpy as np

CANDIDATE_RADII = np.round(np.arange(0.012, 0.0241, 0.002), 6)  # K = 7, unit frame


def candidate_radii(r_min: float, r_max: float, count: int, spacing: str = "linear") -> np.ndarray:
    """``count`` radii from ``r_min`` to ``r_max``, evenly spaced in r (``"linear"``) or in log r
    (``"log"``: a range whose best radii span a factor of several, where the error's minima are
    about as wide in log r at either end); (count,) float64."""
    if count < 3 or not 0 < r_min < r_max:
        raise ValueError("need at least 3 radii and 0 < r_min < r_max")
    if spacing == "log":
        return np.geomspace(r_min, r_max, count)
    if spacing == "linear":
        return np.linspace(r_min, r_max, count)
    raise ValueError(f"spacing must be 'linear' or 'log', not {spacing!r}")


def _grid_coordinate(radii: np.ndarray):
    """The coordinate in which ``radii`` are evenly spaced (r or log r), and its inverse."""
    for forward, inverse in ((lambda r: r, lambda x: x), (np.log, np.exp)):
        x = forward(radii)
        steps = np.diff(x)
        if steps[0] > 0 and np.allclose(steps, steps[0], rtol=1e-6, atol=0):
            return x, inverse
    raise ValueError("candidate radii must be increasing and evenly spaced in r or in log r")


def parabola_targets(errors: np.ndarray, radii: np.ndarray = CANDIDATE_RADII) -> np.ndarray:
    """Target radius per query.

    Parameters
    ----------
    errors : (Q, K) float, absolute UDF error of each query at each candidate radius
    radii : (K,) float, increasing candidate radii, evenly spaced in r or in log r (the
        parabola is then fitted in that coordinate)

    Returns
    -------
    (Q,) float64 target radii, inside [radii[0], radii[-1]]
    """
    errors = np.asarray(errors, dtype=np.float64)
    radii = np.asarray(radii, dtype=np.float64)
    if errors.ndim != 2 or errors.shape[1] != radii.size or radii.size < 3:
        raise ValueError(f"errors must be (Q, {radii.size}) with at least 3 radii")
    x, inverse = _grid_coordinate(radii)
    step = x[1] - x[0]
    best = np.argmin(errors, axis=1)
    targets = x[best].copy()
    inner = (best > 0) & (best < radii.size - 1)
    rows = np.nonzero(inner)[0]
    left = errors[rows, best[rows] - 1]
    mid = errors[rows, best[rows]]
    right = errors[rows, best[rows] + 1]
    curvature = left - 2.0 * mid + right
    convex = curvature > 1e-12 * np.maximum(np.abs(mid), 1e-30)
    rows, left, right, curvature = rows[convex], left[convex], right[convex], curvature[convex]
    # The vertex lies within half a step of the minimum because mid <= left and mid <= right.
    targets[rows] += step * (left - right) / (2.0 * curvature)
    targets = inverse(targets)
    targets[~inner] = radii[best[~inner]]  # exact grid radii where there is no parabola
    return np.clip(targets, radii[0], radii[-1])


def expected_errors(errors: np.ndarray, queries: np.ndarray, neighbours: int) -> np.ndarray:
    """Each query's error curve averaged with those of its nearest queries (itself included).

    Parameters
    ----------
    errors : (Q, K) error curves of the queries of one shape
    queries : (Q, 3) their positions
    neighbours : how many nearest queries to average (1: the curves unchanged)

    Returns
    -------
    (Q, K) float64
    """
    from scipy.spatial import cKDTree

    errors = np.asarray(errors, dtype=np.float64)
    neighbours = min(int(neighbours), len(errors))
    if neighbours <= 1:
        return errors
    _, nearest = cKDTree(queries).query(queries, k=neighbours)
    return errors[nearest].mean(axis=1)


def inset_targets(targets: np.ndarray, r_min: float, r_max: float, inset: float) -> np.ndarray:
    """Targets clipped to ``inset`` of the span inside [r_min, r_max].

    A target at an end of the range asks the sigmoid for 0 or 1, which it reaches only with
    vanishing gradient; a query pinned there also stops the rest from moving (measured: with
    most expected-error targets at 0.024 the selector sat at the top for every query).
    """
    span = r_max - r_min
    return np.clip(targets, r_min + inset * span, r_max - inset * span)


def loss_weights(errors: np.ndarray) -> np.ndarray:
    """Per-query weight w = max(e) - min(e) over the candidate radii; (Q, K) -> (Q,)."""
    errors = np.asarray(errors, dtype=np.float64)
    return errors.max(axis=1) - errors.min(axis=1)


def selector_loss(predicted: np.ndarray, targets: np.ndarray, weights: np.ndarray,
                  r_min: float, r_max: float) -> float:
    """Mean of w * |r_hat - r*| / (r_max - r_min): the paper's loss, in numpy for checking."""
    span = r_max - r_min
    return float(np.mean(weights * np.abs(np.asarray(predicted) - np.asarray(targets)) / span))
