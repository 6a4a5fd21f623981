"""Reconstruction methods the benchmark can run, each a callable ``PointCloud -> Mesh``.

:data:`METHODS` maps a name to a factory; ``make_method(name, **options)`` returns the callable.

* ``poisson``: Open3D screened Poisson (the classic baseline, ``research/evaluation.md`` §4.1).
  Normals are estimated from the 30 nearest neighbours and oriented consistently
  (``orient_normals_consistent_tangent_plane(30)``, on a copy of the points jittered by 1e-4 of
  the extent, so it does not stall on coplanar scans); the solve uses depth 9,
  scale 1.1, ``linear_fit=False`` and one thread (multi-threaded runs differ between calls and
  can crash); the vertices with the lowest 5 % of densities are removed (Poisson extrapolates
  over regions without points). Needs the optional ``open3d-cpu`` package
  (``requirements-bench.txt``).
* ``ours``: :func:`engine.reconstruct.reconstruct` with
  :class:`engine.settings.ReconstructSettings`.
* ``nearest-udf``: ``ours`` with the non-learned nearest-point distance as the UDF
  (``reconstruct(..., udf_source="nearest")``).
* ``truth-udf``: ``ours``' band and mesher on the ground truth's exact distances: the mesher's
  own floor (:mod:`lab.bench.truth_udf`; it is given the ground truth).

A method that is not available (a missing package or engine module, an unsupported mode) raises
:class:`MethodUnavailable` from its factory or on its first call.
"""

from typing import Callable, Dict

import numpy as np

from engine.geometry import Mesh, PointCloud

Method = Callable[[PointCloud], Mesh]


class MethodUnavailable(RuntimeError):
    """The method cannot run here (missing package, engine part not built yet, unsupported mode)."""


# --------------------------------------------------------------------------------------------
# Open3D screened Poisson


def make_poisson(depth: int = 9, knn: int = 30, orient_k: int = 30, trim_quantile: float = 0.05,
                 scale: float = 1.1) -> Method:
    """Open3D screened Poisson with estimated, consistently oriented normals.

    Parameters
    ----------
    depth : octree depth of the solve (9: a 512³ grid over ``scale`` × the bounding cube)
    knn : neighbours used to estimate each normal (PCA of the k nearest points)
    orient_k : neighbours of the graph ``orient_normals_consistent_tangent_plane`` propagates on
    trim_quantile : vertices whose Poisson density is below this quantile are removed
    scale : ratio of the reconstruction cube to the bounding cube of the points

    Returns
    -------
    callable
        ``poisson(cloud) -> Mesh``. Input normals, if any, are ignored: every method gets the same
        points only. Deterministic: one solver thread, a fixed jitter seed.

    Raises
    ------
    MethodUnavailable
        When ``open3d`` cannot be imported.
    """
    try:
        import open3d  # noqa: F401
    except ImportError as error:  # pragma: no cover - depends on the environment
        raise MethodUnavailable("the poisson method needs open3d: "
                                "pip install -r requirements-bench.txt") from error

    def poisson(cloud: PointCloud) -> Mesh:
        import open3d as o3d

        o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
        pcd = o3d.geometry.PointCloud(
            o3d.utility.Vector3dVector(np.asarray(cloud.points, dtype=np.float64)))
        pcd.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn=knn))
        # Orient on a copy jittered by 1e-4 of the extent: on exactly coplanar points (a clean
        # room scan) the orientation stalls, presumably in the Delaunay step that connects its
        # graph. The solve uses the original points.
        points = np.asarray(pcd.points)
        extent = float(np.ptp(points, axis=0).max()) or 1.0
        jitter = np.random.default_rng(0).normal(0.0, 1e-4 * extent, points.shape)
        jittered = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points + jitter))
        jittered.normals = pcd.normals
        jittered.orient_normals_consistent_tangent_plane(orient_k)
        pcd.normals = jittered.normals
        mesh, densities = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(
            pcd, depth=depth, width=0, scale=scale, linear_fit=False, n_threads=1)
        densities = np.asarray(densities)
        if trim_quantile > 0 and len(densities):
            mesh.remove_vertices_by_mask(densities < np.quantile(densities, trim_quantile))
        return Mesh(np.asarray(mesh.vertices, dtype=np.float64).copy(),
                    np.asarray(mesh.triangles, dtype=np.int64).reshape(-1, 3).copy())

    poisson.__name__ = "poisson"
    return poisson


# --------------------------------------------------------------------------------------------
# Our engine


def _reconstruct_function():
    """``engine.reconstruct.reconstruct``, or :class:`MethodUnavailable` if it is not built."""
    try:
        from engine.reconstruct import reconstruct
    except ImportError as error:
        raise MethodUnavailable(f"engine.reconstruct cannot be imported: {error}") from error
    return reconstruct


def make_ours(radius_mode: str = "fixed", resolution: int = 256, device: str = "auto",
              udf_source: str = None, fill_gaps: bool = False, fields: str = None,
              **settings) -> Method:
    """Our reconstruction: :func:`engine.reconstruct.reconstruct` with the given settings.

    Parameters
    ----------
    radius_mode : ``fixed``, ``curvature`` or ``learned``
    resolution : grid cells along the longest side of the bounding box
    device : ``auto``, ``cpu`` or ``cuda``
    udf_source : None (the engine's default, the network) or ``"nearest"``
    fill_gaps : the engine's gap fill; off unless asked for (the engine's default is on), so
        that a result's name (``-gaps``) says which it is
    fields : a folder where each shape's distance field is kept and, on a later call with the
        same points, settings and field code, read back (:mod:`.field_cache`); the callable's
        ``field_from_cache`` then says whether its last mesh came from a kept field
    **settings : further :class:`engine.settings.ReconstructSettings` fields

    Returns
    -------
    callable
        ``ours(cloud) -> Mesh``, named ``ours`` (fixed radius), ``ours-<mode>`` or
        ``nearest-udf``.

    Raises
    ------
    MethodUnavailable
        When the engine's reconstruct module is missing, when the radius mode has no policy yet,
        or when ``reconstruct`` takes no ``udf_source``.
    """
    import inspect

    from engine.settings import ReconstructSettings

    reconstruct = _reconstruct_function()
    config = ReconstructSettings(radius_mode=radius_mode, resolution=resolution, device=device,
                                 fill_gaps=fill_gaps, **settings).validate()
    if radius_mode != "fixed":
        _check_radius_mode(config)
    options = {}
    if udf_source is not None:
        if "udf_source" not in inspect.signature(reconstruct).parameters:
            raise MethodUnavailable("engine.reconstruct takes no udf_source yet")
        options["udf_source"] = udf_source

    def ours(cloud: PointCloud) -> Mesh:
        if fields is None:
            return reconstruct(cloud, config, None, None, **options).mesh
        from .field_cache import kept_fields

        with kept_fields(fields):
            result = reconstruct(cloud, config, None, None, **options)
        ours.field_from_cache = bool(result.stats.get("from_cache"))
        return result.mesh

    ours.field_from_cache = False

    if udf_source == "nearest":
        ours.__name__ = "nearest-udf"
    else:
        ours.__name__ = ours_name(radius_mode, config.radius, config.fill_gaps)
    return ours


def ours_name(radius_mode: str = "fixed", radius: float = None, fill_gaps: bool = False) -> str:
    """The result name of ours: ``ours`` (fixed, default radius), ``ours-r<radius>`` (fixed,
    another radius) or ``ours-<mode>``, with ``-gaps`` appended when it fills the gaps of sparse
    scans; the JSON files are named after it."""
    from engine.settings import ReconstructSettings

    gaps = "-gaps" if fill_gaps else ""
    if radius_mode != "fixed":
        return f"ours-{radius_mode}{gaps}"
    if radius is None or radius == ReconstructSettings().radius:
        return f"ours{gaps}"
    return f"ours-r{radius:g}{gaps}"


def _check_radius_mode(config) -> None:
    """Raise :class:`MethodUnavailable` when the engine has no policy for the radius mode."""
    try:
        from engine.radius import POLICIES
    except ImportError:
        return  # let the engine report it
    if config.radius_mode not in POLICIES:
        raise MethodUnavailable(f"radius mode {config.radius_mode!r} is not built yet "
                                f"(available: {', '.join(POLICIES)})")


def make_nearest_udf(resolution: int = 256, device: str = "auto", **settings) -> Method:
    """``ours`` with the distance to the nearest input point as the UDF (no learned backbone).

    The non-learned baseline: the same band, mesher and settings as ``ours`` (fixed radius).
    """
    return make_ours(radius_mode="fixed", resolution=resolution, device=device,
                     udf_source="nearest", **settings)


def make_truth_udf(resolution: int = 256, device: str = "auto", **settings):
    """``ours``' band and mesher on the ground truth's exact distances (:mod:`.truth_udf`); the
    callable takes ``(cloud, gt)`` and says so with ``needs_ground_truth``."""
    from .truth_udf import make_truth_udf as make

    return make(resolution=resolution, device=device, **settings)


METHODS: Dict[str, Callable[..., Method]] = {
    "poisson": make_poisson,
    "ours": make_ours,
    "nearest-udf": make_nearest_udf,
    "truth-udf": make_truth_udf,
}


def make_method(name: str, **options) -> Method:
    """The method registered as ``name``, built with ``options`` (see each factory).

    Raises
    ------
    KeyError
        For an unknown name.
    MethodUnavailable
        When the method cannot run here.
    """
    if name not in METHODS:
        raise KeyError(f"unknown method {name!r}; known: {', '.join(METHODS)}")
    return METHODS[name](**options)
