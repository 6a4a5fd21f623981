"""Off-grid target radii for training the radius selector, from cached UDF-error curves.

For each training query the frozen backbone's absolute UDF error is measured at K candidate radii
(the paper: 0.012, 0.014, ..., 0.024 in the unit frame). The target r* is the vertex of the
parabola through the grid minimum and its two neighbours; at either end of the grid, or where the
three points are not convex, r* falls back to the grid minimum. Each query's loss is weighted by
how much the radius matters there, w = max(e) - min(e): a flat curve teaches nothing.
"""

import numpy as np

CANDIDATE_RADII = np.round(np.arange(0.012, 0.0241, 0.002), 6)  # K = 7, unit frame


def parabola_targets(errors: np.ndarray, radii: np.ndarray = CANDIDATE_RADII) -> np.ndarray:
    """Target radius per query.

    Parameters
    ----------
    errors : (Q, K) float, absolute UDF error of each query at each candidate radius
    radii : (K,) float, evenly spaced increasing candidate radii

    Returns
    -------
    (Q,) float64 target radii, inside [radii[0], radii[-1]]
    """
    errors = np.asarray(errors, dtype=np.float64)
    radii = np.asarray(radii, dtype=np.float64)
    steps = np.diff(radii)
    if errors.ndim != 2 or errors.shape[1] != radii.size or radii.size < 3:
        raise ValueError(f"errors must be (Q, {radii.size}) with at least 3 radii")
    if not np.allclose(steps, steps[0]) or steps[0] <= 0:
        raise ValueError("candidate radii must be evenly spaced and increasing")
    best = np.argmin(errors, axis=1)
    targets = radii[best].copy()
    inner = (best > 0) & (best < radii.size - 1)
    rows = np.nonzero(inner)[0]
    left = errors[rows, best[rows] - 1]
    mid = errors[rows, best[rows]]
    right = errors[rows, best[rows] + 1]
    curvature = left - 2.0 * mid + right
    convex = curvature > 1e-12 * np.maximum(np.abs(mid), 1e-30)
    rows, left, right, curvature = rows[convex], left[convex], right[convex], curvature[convex]
    # The vertex lies within half a step of the minimum because mid <= left and mid <= right.
    targets[rows] += steps[0] * (left - right) / (2.0 * curvature)
    return targets


def loss_weights(errors: np.ndarray) -> np.ndarray:
    """Per-query weight w = max(e) - min(e) over the candidate radii; (Q, K) -> (Q,)."""
    errors = np.asarray(errors, dtype=np.float64)
    return errors.max(axis=1) - errors.min(axis=1)


def selector_loss(predicted: np.ndarray, targets: np.ndarray, weights: np.ndarray,
                  r_min: float, r_max: float) -> float:
    """Mean of w * |r_hat - r*| / (r_max - r_min): the paper's loss, in numpy for checking."""
    span = r_max - r_min
    return float(np.mean(weights * np.abs(np.asarray(predicted) - np.asarray(targets)) / span))
