"""Radius policies: the backbone's ball radius for each query.

``fixed`` gives every query the settings' radius (LoSF-UDF). ``curvature`` (a GeoLA-style
heuristic, :mod:`.curvature`) and ``learned`` (the selector network) choose a radius per query in
[rho_min * R, rho_max * R] from the points of the parent ball of radius R. Each of the two has
its own range (``engine.settings.MODE_RANGES``) unless the settings ask for a custom one
(``engine.settings.radius_range``): the selector's is the range it was trained for, wider than the
curvature heuristic's, which on clean scans wants nothing past 0.024.
"""

import functools
from typing import Callable, Dict, Optional

import numpy as np

from .cpu_threads import cpu_threads
from .devices import resolve_device
from .errors import InputError
from .patches import Neighbours
from .settings import ReconstructSettings, radius_range

RadiusPolicy = Callable[..., np.ndarray]


def fixed_radii(settings: ReconstructSettings, tree, points: np.ndarray,
                queries: np.ndarray, neighbours: Optional[Neighbours] = None) -> np.ndarray:
    """Every query gets ``settings.radius``: (Q,) float64, unit frame."""
    return np.full(len(queries), float(settings.radius), dtype=np.float64)


def curvature_policy(settings: ReconstructSettings, tree, points: np.ndarray,
                     queries: np.ndarray, neighbours: Optional[Neighbours] = None) -> np.ndarray:
    """Smaller balls where the parent ball's surface variation is larger: (Q,) float64."""
    from .curvature import curvature_radii

    return curvature_radii(tree, points, queries, *radius_range(settings), neighbours)


def learned_policy(settings: ReconstructSettings, tree, points: np.ndarray,
                   queries: np.ndarray, neighbours: Optional[Neighbours] = None) -> np.ndarray:
    """The selector network's radius per query, in [rho_min R, rho_max R]: (Q,) float64."""
    from .selector import predict_radii

    device = resolve_device(settings.device)
    return predict_radii(_shipped_selector(device), tree, points, queries,
                         *radius_range(settings), neighbours,
                         cpu_threads() if device == "cpu" else 1)


@functools.lru_cache(maxsize=2)
def _shipped_selector(device: str = "cpu"):
    """The shipped selector, loaded once per process and device (the field asks batch after
    batch): numpy on ``cpu``, torch on ``cuda``."""
    from .selector import TorchSelector, load_selector_numpy, load_selector_torch

    if device == "cpu":
        return load_selector_numpy()
    return TorchSelector(load_selector_torch(device=device), device)


POLICIES: Dict[str, RadiusPolicy] = {
    "fixed": fixed_radii,
    "curvature": curvature_policy,
    "learned": learned_policy,
}


def require_policy(settings: ReconstructSettings) -> RadiusPolicy:
    """The policy of ``settings.radius_mode``; :class:`InputError` for an unknown mode."""
    policy = POLICIES.get(settings.radius_mode)
    if policy is None:
        raise InputError(f"radius mode must be one of {', '.join(POLICIES)}, "
                         f"not {settings.radius_mode!r}")
    return policy


def max_radius(settings: ReconstructSettings) -> float:
    """The largest radius the policy of ``settings`` can return (unit frame).

    The balls of the field's queries reach this far (a tile's points reach past its core by
    it); the field's band is every grid node within it of an input point, up to
    ``engine.field.BAND_RADIUS_CAP``.
    """
    if settings.radius_mode == "fixed":
        return float(settings.radius)
    parent_radius, _, rho_max = radius_range(settings)
    return float(rho_max * parent_radius)


def reads_parent_ball(settings: ReconstructSettings) -> bool:
    """Whether the policy of ``settings`` reads each query's parent ball (all but ``fixed``)."""
    return settings.radius_mode != "fixed"


def parent_ball(settings: ReconstructSettings, tree, queries: np.ndarray) -> Neighbours:
    """The nearest points within the parent radius R of each query, as the policies read them.

    The lists hold the selector's PARENT_POINTS (64) nearest, as many as the curvature estimate
    and the backbone's patch need: both are cut from them (:func:`patches_from_neighbours`).
    """
    from .selector import parent_neighbours

    return parent_neighbours(tree, queries, radius_range(settings)[0])


def radii_for_queries(settings: ReconstructSettings, tree, points: np.ndarray,
                      queries: np.ndarray, neighbours: Optional[Neighbours] = None,
                      ) -> np.ndarray:
    """The ball radius of each query under ``settings.radius_mode``.

    Parameters
    ----------
    settings : ReconstructSettings
        ``radius_mode`` picks the policy; ``radius`` or ``radius_range(settings)`` bounds it.
    tree : scipy.spatial.cKDTree
        Built over ``points``.
    points : (N, 3) float array
        Input points, unit frame.
    queries : (Q, 3) float array
        Query positions, unit frame.
    neighbours : Neighbours, optional
        The queries' :func:`parent_ball`, when the caller has it (looked up otherwise).

    Returns
    -------
    (Q,) float64
        Radii in the unit frame, each in (0, :func:`max_radius`].

    Raises
    ------
    InputError
        When the radius mode is unknown.
    """
    radii = require_policy(settings)(settings, tree, points, queries, neighbours)
    return np.minimum(radii, max_radius(settings))
