"""A virtual scanner: points a few scanner positions would see, with realistic density.

Occlusion comes from one spherical depth map per viewpoint, made by splatting dense surface
samples into an equirectangular z-buffer: each splat covers the pixels its share of the surface
subtends (so occluders have no holes) and writes its tangent plane's depth along each pixel ray
(so oblique surfaces do not hide themselves). A candidate sample is visible from a viewpoint when
it faces it and its tangent plane's depth along its pixel's ray is at most the stored depth plus
a small slack.
Visible candidates are kept with probability proportional to sum over viewpoints of
cos(angle) / max(distance, near)^2, so density falls off with distance and obliquity.
"""

from functools import lru_cache
from typing import Callable, Optional, Tuple

import numpy as np

from engine.geometry import Mesh
from engine.sampling import face_areas_and_normals, sample_surface

ROWS = 512  # depth-map height; the width is 2 * ROWS (square pixels of pi / ROWS radians)
SPLATS = 200_000  # surface samples splatted into each depth map
MAX_SPLAT = 12  # pixels: the largest splat half-width


def _spherical(points: np.ndarray, eye: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distance (N,), flat pixel index (N,) and cos(elevation) (N,) of points seen from ``eye``."""
    rel = points - eye
    dist = np.maximum(np.linalg.norm(rel, axis=1), 1e-12)
    elevation = np.arcsin(np.clip(rel[:, 2] / dist, -1.0, 1.0))
    azimuth = np.arctan2(rel[:, 1], rel[:, 0])
    pitch = np.pi / ROWS
    row = np.clip(((elevation + np.pi / 2) / pitch).astype(np.int64), 0, ROWS - 1)
    col = ((azimuth + np.pi) / pitch).astype(np.int64) % (2 * ROWS)
    return dist, row * 2 * ROWS + col, np.cos(elevation)


@lru_cache(maxsize=1)
def _pixel_rays() -> np.ndarray:
    """Unit direction (ROWS * 2 * ROWS, 3) through each depth-map pixel's centre."""
    pitch = np.pi / ROWS
    elevation = (np.arange(ROWS) + 0.5) * pitch - np.pi / 2
    azimuth = (np.arange(2 * ROWS) + 0.5) * pitch - np.pi
    el, az = np.meshgrid(elevation, azimuth, indexing="ij")
    rays = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], -1)
    return rays.reshape(-1, 3).astype(np.float32)


def _plane_depth(points: np.ndarray, normals: np.ndarray, eye: np.ndarray, dist: np.ndarray,
                 pixels: np.ndarray) -> np.ndarray:
    """Depth along pixel-centre rays of each point's tangent plane.

    points, normals: (N, 3); dist: (N,) the points' own depths; pixels: (N, K) pixel indices.
    Returns (N, K) float32: where the ray is parallel to the plane the point's own depth, and always
    within [dist / 2, 2 * dist] so a grazing plane cannot reach far.
    """
    num = np.einsum("ij,ij->i", normals, points - eye).astype(np.float32)[:, None]
    den = np.einsum("ikj,ij->ik", _pixel_rays()[pixels], normals.astype(np.float32))
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = num / den
    own = dist.astype(np.float32)[:, None]
    depth = np.where(depth > 0, depth, own)  # parallel or behind: NaN, inf or negative
    return np.minimum(np.maximum(depth, own / 2), own * 2)


def depth_map(splats: np.ndarray, normals: np.ndarray, spacing: float,
              eye: np.ndarray) -> np.ndarray:
    """Equirectangular z-buffer (ROWS * 2 * ROWS,) of distances from ``eye``; inf where empty.

    Each splat is a small disc of its tangent plane: it writes the plane's depth along every
    pixel ray it covers, so a flat surface's stored depth is exact whatever its obliquity.

    Parameters
    ----------
    splats, normals : (M, 3) surface samples and their unit normals, same units as ``eye`` (3,)
    spacing : mean distance between neighbouring splats; sets each splat's angular radius
    """
    dist, pixel, cos_el = _spherical(splats, eye)
    row, col = np.divmod(pixel, 2 * ROWS)
    pitch = np.pi / ROWS
    angle = 1.2 * spacing / dist
    half_r = np.clip(np.ceil(angle / pitch), 1, MAX_SPLAT).astype(np.int64)
    half_c = np.ceil(angle / (pitch * np.maximum(cos_el, 1e-3)))  # columns narrow toward the poles
    half_c = np.clip(half_c, 1, 4 * MAX_SPLAT).astype(np.int64)
    zbuf = np.full(ROWS * 2 * ROWS, np.inf, dtype=np.float32)
    keys = half_r * 1000 + half_c
    order = np.argsort(keys, kind="stable")
    for sel in np.split(order, np.flatnonzero(np.diff(keys[order])) + 1):  # one footprint size each
        hr, hc = divmod(int(keys[sel[0]]), 1000)
        dr, dc = np.meshgrid(np.arange(-hr, hr + 1), np.arange(-hc, hc + 1), indexing="ij")
        rows = np.clip(row[sel, None] + dr.ravel(), 0, ROWS - 1)
        cols = (col[sel, None] + dc.ravel()) % (2 * ROWS)
        covered = rows * 2 * ROWS + cols
        depth = _plane_depth(splats[sel], normals[sel], eye, dist[sel], covered)
        np.minimum.at(zbuf, covered.ravel(), depth.ravel())
    return zbuf


def density_field(rng: np.random.Generator, floor: float = 0.08,
                  wavelength: float = 0.35) -> Callable[[np.ndarray], np.ndarray]:
    """A smooth random density: a function from points (N, 3) to values (N,) in [floor, 1].

    A sum of 8 random plane waves of about ``wavelength`` (unit-frame lengths), squashed by tanh:
    about half the surface is dense, half sparse, with smooth transitions.
    """
    freq = rng.normal(size=(8, 3)) * (2 * np.pi / wavelength) / np.sqrt(3)
    phase = rng.uniform(0, 2 * np.pi, 8)

    def density(points: np.ndarray) -> np.ndarray:
        g = np.sin(points @ freq.T + phase).sum(axis=1) / 2.0
        return floor + (1 - floor) * 0.5 * (1 + np.tanh(1.5 * g))

    return density


def default_viewpoints(vertices: np.ndarray, rng: np.random.Generator,
                       count: int = 4) -> np.ndarray:
    """``count`` (K, 3) positions around an object, 1.5 bounding radii from its centre.

    Azimuths are spread evenly with jitter, elevations drawn in -10..60 degrees.
    """
    lo, hi = vertices.min(0), vertices.max(0)
    centre, radius = (lo + hi) / 2, np.linalg.norm(hi - lo) / 2
    azimuth = (rng.uniform(0, 2 * np.pi) + np.arange(count) * 2 * np.pi / count
               + rng.uniform(-0.4, 0.4, count))
    elevation = np.radians(rng.uniform(-10, 60, count))
    direction = np.stack([np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth),
                          np.sin(elevation)], 1)
    return centre + 1.5 * radius * direction


def virtual_scan(mesh: Mesh, count: int, rng: np.random.Generator,
                 viewpoints: Optional[np.ndarray] = None, uneven: bool = False,
                 near: float = 0.16, slack: float = 0.002) -> Tuple[np.ndarray, np.ndarray]:
    """Scan ``mesh`` from a few positions and return ``count`` visible points.

    Parameters
    ----------
    mesh : the surface, with faces oriented toward where it can be seen from (one-sided sheets)
    count : number of points to return
    rng : the caller's generator; independent streams for depth maps, candidates, acceptance
        and the density field are spawned from it
    viewpoints : (K, 3) scanner positions in mesh units; None puts 4 around the object
    uneven : multiply the acceptance by a smooth random density field (see ``density_field``)
    near : distance d0 below which density stops growing (0.16 ~ 0.8 m in a 5 m room)
    slack : depth tolerance of the visibility test (mesh units; 0.002 ~ 1 cm in a 5 m room)

    Returns
    -------
    points : (count, 3) float64 on the visible surface
    normals : (count, 3) float64, the unit normal of the face each point lies on
    """
    vertices, faces = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces)
    rng_splat, rng_view, rng_cand, rng_accept, rng_field = rng.spawn(5)
    if viewpoints is None:
        viewpoints = default_viewpoints(vertices, rng_view)
    viewpoints = np.asarray(viewpoints, dtype=np.float64).reshape(-1, 3)
    density = density_field(rng_field) if uneven else None

    area = face_areas_and_normals(vertices, faces)[0].sum()
    spacing = np.sqrt(area / SPLATS)
    splats, splat_normals, _ = sample_surface(vertices, faces, SPLATS, rng_splat)
    zbufs = [depth_map(splats, splat_normals, spacing, eye) for eye in viewpoints]

    def weight(points: np.ndarray, normals: np.ndarray) -> np.ndarray:
        total = np.zeros(len(points))
        for eye, zbuf in zip(viewpoints, zbufs):
            dist, pixel, _ = _spherical(points, eye)
            facing = np.clip(np.einsum("ij,ij->i", normals, eye - points) / dist, 0.0, 1.0)
            own = _plane_depth(points, normals, eye, dist, pixel[:, None])[:, 0]
            visible = own <= zbuf[pixel] + slack
            total += visible * facing / np.maximum(dist, near) ** 2
        if density is not None:
            total *= density(points)
        return total

    kept_p, kept_n, have, scale = [], [], 0, None
    batch = max(4 * count, 100_000)
    for _round in range(200):
        pts, nrm, _ = sample_surface(vertices, faces, batch, rng_cand)
        w = weight(pts, nrm)
        if scale is None:
            scale = w.max()
            if scale <= 0:
                raise ValueError("no part of the mesh is visible from the viewpoints")
        keep = rng_accept.random(batch) < w / scale
        kept_p.append(pts[keep])
        kept_n.append(nrm[keep])
        have += int(keep.sum())
        if have >= count:
            break
    else:
        raise ValueError("the virtual scan kept too few points; check the viewpoints")
    return np.concatenate(kept_p)[:count], np.concatenate(kept_n)[:count]

