"""Analytic surfaces with exact distances and closest points, for tests and benchmarks.

Each shape is a callable ``shape(points (P, 3)) -> (distances (P,), closest points (P, 3))`` in
world units, the ``exact`` form :class:`~engine.udf_grid.UDFGrid` accepts. :func:`sample_grid` bakes
one into a grid over a box.
"""

from typing import Callable, Sequence, Tuple

import numpy as np

from engine.udf_grid import UDFGrid

Shape = Callable[[np.ndarray], Tuple[np.ndarray, np.ndarray]]


def _result(points: np.ndarray, closest: np.ndarray):
    return np.linalg.norm(points - closest, axis=1), closest


def sphere(center=(0.0, 0.0, 0.0), radius: float = 0.5) -> Shape:
    """A closed sphere."""
    c = np.asarray(center, dtype=np.float64)

    def fn(p):
        v = p - c
        n = np.linalg.norm(v, axis=1, keepdims=True)
        v = np.where(n > 1e-12, v / np.maximum(n, 1e-12), np.array([0.0, 0.0, 1.0]))
        return _result(p, c + radius * v)
    return fn


def hemisphere(center=(0.0, 0.0, 0.0), radius: float = 0.5) -> Shape:
    """The upper half (z >= center z) of a sphere: open, one boundary circle."""
    c = np.asarray(center, dtype=np.float64)

    def fn(p):
        v = p - c
        below = v[:, 2] < 0
        v[below, 2] = 0.0
        n = np.linalg.norm(v, axis=1, keepdims=True)
        v = np.where(n > 1e-12, v / np.maximum(n, 1e-12), np.array([1.0, 0.0, 0.0]))
        return _result(p, c + radius * v)
    return fn


def torus(center=(0.0, 0.0, 0.0), major: float = 0.35, minor: float = 0.15) -> Shape:
    """A closed torus around the z axis."""
    c = np.asarray(center, dtype=np.float64)

    def fn(p):
        v = p - c
        rho = np.hypot(v[:, 0], v[:, 1])
        ring = np.zeros_like(v)
        safe = np.maximum(rho, 1e-12)
        ring[:, 0] = np.where(rho > 1e-12, v[:, 0] / safe, 1.0) * major
        ring[:, 1] = np.where(rho > 1e-12, v[:, 1] / safe, 0.0) * major
        w = v - ring
        n = np.linalg.norm(w, axis=1, keepdims=True)
        w = np.where(n > 1e-12, w / np.maximum(n, 1e-12), np.array([0.0, 0.0, 1.0]))
        return _result(p, c + ring + minor * w)
    return fn


def disk(center=(0.0, 0.0, 0.0), radius: float = 0.5, normal=(0.0, 0.0, 1.0)) -> Shape:
    """A flat open disk: one boundary circle."""
    c = np.asarray(center, dtype=np.float64)
    nrm = np.asarray(normal, dtype=np.float64)
    nrm = nrm / np.linalg.norm(nrm)

    def fn(p):
        v = p - c
        v = v - np.outer(v @ nrm, nrm)
        r = np.linalg.norm(v, axis=1, keepdims=True)
        v = np.where(r > radius, v * (radius / np.maximum(r, 1e-12)), v)
        return _result(p, c + v)
    return fn


def rectangle(center=(0.0, 0.0, 0.0), u=(1.0, 0.0, 0.0), v=(0.0, 1.0, 0.0),
              half_u: float = 0.4, half_v: float = 0.4) -> Shape:
    """A flat rectangle ``center + s u + t v`` with ``|s| <= half_u``, ``|t| <= half_v``."""
    c = np.asarray(center, dtype=np.float64)
    u = np.asarray(u, dtype=np.float64) / np.linalg.norm(u)
    v = np.asarray(v, dtype=np.float64) / np.linalg.norm(v)

    def fn(p):
        q = p - c
        s = np.clip(q @ u, -half_u, half_u)
        t = np.clip(q @ v, -half_v, half_v)
        return _result(p, c + np.outer(s, u) + np.outer(t, v))
    return fn


def perforated_plate(center=(0.0, 0.0, 0.0), half: float = 0.35, holes: int = 4,
                     hole_radius: float = 0.05) -> Shape:
    """A square plate in the plane ``z = center[2]`` (side ``2 half``) with ``holes x holes``
    round holes of ``hole_radius`` on a regular grid: a grille. Its double cover has a handle
    through every hole."""
    c = np.asarray(center, dtype=np.float64)
    pitch = 2.0 * half / holes
    centres = -half + pitch * (np.arange(holes) + 0.5)

    def fn(p):
        q = p - c
        flat = np.clip(q[:, :2], -half, half)  # the nearest point of the square, holes aside
        cell = np.clip(np.floor((flat + half) / pitch), 0, holes - 1).astype(int)
        hole = np.stack([centres[cell[:, 0]], centres[cell[:, 1]]], axis=1)
        offset = flat - hole
        rho = np.linalg.norm(offset, axis=1, keepdims=True)
        inside = rho[:, 0] < hole_radius  # the nearest point is on the hole's rim instead
        rim = hole + offset * (hole_radius / np.maximum(rho, 1e-12))
        flat = np.where(inside[:, None], rim, flat)
        closest = np.column_stack([flat, np.zeros(len(p))]) + c
        return _result(p, closest)
    return fn


def union(*shapes: Shape) -> Shape:
    """The union of several shapes: the nearest of their closest points."""

    def fn(p):
        best_d, best_c = shapes[0](p)
        best_c = best_c.copy()
        for shape in shapes[1:]:
            d, c = shape(p)
            closer = d < best_d
            best_d = np.where(closer, d, best_d)
            best_c[closer] = c[closer]
        return best_d, best_c
    return fn


def t_junction(half_width: float = 0.35, depth: float = 0.35) -> Shape:
    """Three half-squares meeting along the z axis (a non-manifold 'T': a wall and a fin)."""
    wall = rectangle((0, 0, 0), (1, 0, 0), (0, 0, 1), half_width, depth)
    fin = rectangle((0, half_width / 2, 0), (0, 1, 0), (0, 0, 1), half_width / 2, depth)
    return union(wall, fin)


def shelf_on_wall(width: float = 0.3, height: float = 0.35, depth: float = 0.25,
                  shelf_z: float = 0.03) -> Shape:
    """A wall (the plane y = 0) with a narrower shelf (z = shelf_z) touching it along a line."""
    wall = rectangle((0, 0, 0), (1, 0, 0), (0, 0, 1), width, height)
    shelf = rectangle((0, depth / 2, shelf_z), (1, 0, 0), (0, 1, 0), 0.6 * width, depth / 2)
    return union(wall, shelf)


def box_surface(center=(0.0, 0.0, 0.0), half=(0.2, 0.2, 0.2)) -> Tuple[Shape, ...]:
    """The six faces of an axis-aligned box, as rectangles."""
    c = np.asarray(center, dtype=np.float64)
    h = np.asarray(half, dtype=np.float64)
    faces = []
    for axis in range(3):
        u, v = [a for a in range(3) if a != axis]
        for sign in (-1.0, 1.0):
            centre = c.copy()
            centre[axis] += sign * h[axis]
            faces.append(rectangle(centre, np.eye(3)[u], np.eye(3)[v], h[u], h[v]))
    return tuple(faces)


def touching_boxes(half: float = 0.15, offset=(0.011, 0.007, 0.013)) -> Shape:
    """Two equal boxes side by side sharing one face (the shared face counts once)."""
    o = np.asarray(offset, dtype=np.float64)
    left = box_surface(o + (-half, 0, 0), (half, half, half))
    right = box_surface(o + (half, 0, 0), (half, half, half))
    return union(*left, *right[1:])  # right[0] is the face at x = 0, left[1] already has it


def mobius(radius: float = 0.35, half_width: float = 0.15, spacing: float = 0.002) -> Shape:
    """A Möbius strip around the z axis, represented by dense samples (``spacing`` apart).

    Closest points are the nearest sample projected on its tangent plane (error far below a
    voxel when ``spacing`` is a fraction of it).
    """
    from scipy.spatial import cKDTree

    nu = int(np.ceil(2 * np.pi * (radius + half_width) / spacing))
    nv = int(np.ceil(2 * half_width / spacing)) + 1
    u = np.linspace(0, 2 * np.pi, nu, endpoint=False)[:, None]
    s = np.linspace(-half_width, half_width, nv)[None, :]

    def point(u, s):
        return np.stack([(radius + s * np.cos(u / 2)) * np.cos(u),
                         (radius + s * np.cos(u / 2)) * np.sin(u),
                         s * np.sin(u / 2) * np.ones_like(u)], axis=-1)

    samples = point(u, s).reshape(-1, 3)
    eps = 1e-6
    du = (point(u + eps, s) - point(u - eps, s)).reshape(-1, 3)
    ds = (point(u, s + eps) - point(u, s - eps)).reshape(-1, 3)
    normals = np.cross(du, ds)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    tree = cKDTree(samples)
    coarse = np.arange(0, len(samples), 97)
    coarse_tree = cKDTree(samples[coarse])  # far queries: a coarse answer is enough

    def fn(p):
        _, i = tree.query(p, distance_upper_bound=16 * spacing)
        miss = i >= len(samples)
        if miss.any():
            i[miss] = coarse[coarse_tree.query(p[miss])[1]]
        q = p - samples[i]
        c = p - normals[i] * np.einsum("ij,ij->i", q, normals[i])[:, None]
        far = np.linalg.norm(c - samples[i], axis=1) > spacing  # past the rim: keep the sample
        c[far] = samples[i][far]
        return _result(p, c)
    return fn


def sample_grid(shape: Shape, lo: Sequence[float], hi: Sequence[float], resolution: int,
                exact: bool = True) -> UDFGrid:
    """Bake ``shape`` into a dense grid over the box ``[lo, hi]``.

    The spacing is ``max(hi - lo) / (resolution - 1)`` (isotropic voxels); each axis gets as
    many nodes as cover its side from ``lo``. With ``exact`` the grid queries the shape itself
    during the optimisation.
    """
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    spacing = float(np.max(hi - lo)) / (resolution - 1)
    dims = np.ceil((hi - lo) / spacing - 1e-9).astype(int) + 1
    axes = [lo[a] + spacing * np.arange(dims[a]) for a in range(3)]
    udf = np.empty(tuple(dims), dtype=np.float32)
    for i, x in enumerate(axes[0]):
        yy, zz = np.meshgrid(axes[1], axes[2], indexing="ij")
        pts = np.stack([np.full(yy.size, x), yy.ravel(), zz.ravel()], axis=1)
        udf[i] = shape(pts)[0].reshape(yy.shape)
    return UDFGrid(udf, lo, spacing, exact=shape if exact else None)
