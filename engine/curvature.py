"""The curvature radius policy: smaller balls where the surface bends (the GeoLA idea).

GeoLA's exact rule is not public, so this is our own, documented design. For each query the
points of its parent ball (radius R) are summarised by their *surface variation*
sigma = l0 / (l0 + l1 + l2), where l0 <= l1 <= l2 are the eigenvalues of their covariance:
0 on a plane, growing with curvature, creases, corners and with a second sheet inside the ball
(the thin structures where a large ball mixes both sides), at most 1/3 for an isotropic blob.
sigma is mapped monotonically and linearly onto the radius range:

    t   = clamp((sigma - SIGMA_FLAT) / (SIGMA_DETAILED - SIGMA_FLAT), 0, 1)
    rho = rho_max - (rho_max - rho_min) * t,    r = rho * R

Balls with fewer than MIN_POINTS points cannot tell a surface from noise and keep rho_max: a
sparse region needs the larger ball to see anything at all. Known weakness, by design of any
curvature heuristic: Gaussian noise also raises sigma, so on noisy scans this policy shrinks the
ball where a larger one would average the noise away (the learned selector can learn better).
"""

from typing import Optional

import numpy as np

from .patches import Neighbours, gather_patches, patches_from_neighbours

# Measured through a ball of R = 0.024 at benchmark density (~33k points per unit area): a
# cylinder of radius 0.1 gives sigma = 0.002, radius 0.03 gives 0.013, radius 0.015 gives 0.065,
# a 90-degree crease 0.07, a plane with noise 0.0025 gives 0.022. Below FLAT the full radius is
# used, above DETAILED the smallest.
SIGMA_FLAT = 0.002
SIGMA_DETAILED = 0.05
MIN_POINTS = 6
PARENT_POINTS = 64


def surface_variation(tree, points: np.ndarray, queries: np.ndarray, parent_radius: float,
                      neighbours: Optional[Neighbours] = None) -> tuple:
    """Surface variation of each query's parent ball.

    Parameters
    ----------
    tree : scipy.spatial.cKDTree over ``points``
    points : (N, 3) float, unit frame
    queries : (Q, 3) float, unit frame
    parent_radius : float, R in the unit frame
    neighbours : optional, the nearest points within R of each query (at least PARENT_POINTS
        per list; see :func:`engine.patches.nearest_within`), when the caller has them already

    Returns
    -------
    sigma : (Q,) float64 in [0, 1/3]; 0 where the ball holds fewer than 3 points
    counts : (Q,) int64, points used per ball (at most PARENT_POINTS nearest)
    """
    if neighbours is None:
        rel, mask, counts = gather_patches(tree, points, queries, parent_radius, PARENT_POINTS)
    else:
        rel, mask, counts = patches_from_neighbours(points, queries, neighbours, parent_radius,
                                                    PARENT_POINTS)
    weights = mask.astype(np.float64)
    n = np.maximum(counts, 1).astype(np.float64)
    mean = np.einsum("qk,qkc->qc", weights, rel) / n[:, None]
    centred = (rel - mean[:, None, :]) * weights[:, :, None]
    covariance = np.einsum("qka,qkb->qab", centred, centred) / n[:, None, None]
    eigenvalues = np.linalg.eigvalsh(covariance)  # ascending
    total = eigenvalues.sum(axis=1)
    sigma = np.divide(eigenvalues[:, 0], total, out=np.zeros_like(total), where=total > 0)
    sigma[counts < 3] = 0.0
    return np.clip(sigma, 0.0, 1.0 / 3.0), counts


def curvature_radii(tree, points: np.ndarray, queries: np.ndarray, parent_radius: float,
                    rho_min: float, rho_max: float,
                    neighbours: Optional[Neighbours] = None) -> np.ndarray:
    """Per-query ball radius in [rho_min * R, rho_max * R], smaller where sigma is larger.

    Returns
    -------
    (Q,) float64 radii in the unit frame
    """
    sigma, counts = surface_variation(tree, points, queries, parent_radius, neighbours)
    t = np.clip((sigma - SIGMA_FLAT) / (SIGMA_DETAILED - SIGMA_FLAT), 0.0, 1.0)
    t[counts < MIN_POINTS] = 0.0
    rho = rho_max - (rho_max - rho_min) * t
    return rho * parent_radius
