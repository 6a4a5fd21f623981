"""Small mesh builders the procedural shapes are assembled from.

Every builder returns a ``Part``: ``(vertices (V, 3) float64, faces (F, 3) int64)`` with
counter-clockwise faces seen from the side the normal points to (outward for closed parts).
Parts are concatenated, never unioned, like the parts of a ShapeNet model.
"""

from typing import Iterable, Optional, Sequence, Tuple

import numpy as np

Part = Tuple[np.ndarray, np.ndarray]


def grid_faces(nu: int, nv: int, wrap_u: bool = False, wrap_v: bool = False) -> np.ndarray:
    """Triangles of an ``nu`` x ``nv`` vertex grid whose vertex (i, j) has index ``i * nv + j``.

    Returns (F, 3) int64; with ``wrap_u`` the last row joins the first (a tube), likewise
    ``wrap_v``.
    The triangle normal is d/du x d/dv.
    """
    iu = np.arange(nu if wrap_u else nu - 1)
    iv = np.arange(nv if wrap_v else nv - 1)
    i, j = np.meshgrid(iu, iv, indexing="ij")
    i, j = i.ravel(), j.ravel()
    i1, j1 = (i + 1) % nu, (j + 1) % nv
    a, b, c, d = i * nv + j, i1 * nv + j, i1 * nv + j1, i * nv + j1
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int64)


def concat(parts: Iterable[Part]) -> Part:
    """Concatenate parts into one vertex and face array (no welding across parts)."""
    vertices, faces, offset = [], [], 0
    for v, f in parts:
        vertices.append(np.asarray(v, dtype=np.float64))
        faces.append(np.asarray(f, dtype=np.int64) + offset)
        offset += len(v)
    return np.concatenate(vertices), np.concatenate(faces)


def transform(part: Part, rotation: Optional[np.ndarray] = None,
              translation: Sequence[float] = (0.0, 0.0, 0.0)) -> Part:
    """Rotate (3, 3) then translate (3,) a part."""
    v, f = part
    if rotation is not None:
        v = v @ np.asarray(rotation).T
    return v + np.asarray(translation, dtype=np.float64), f


def rotation_z(angle: float) -> np.ndarray:
    """(3, 3) rotation by ``angle`` radians about +z."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def frame_from_axis(axis: Sequence[float]) -> np.ndarray:
    """(3, 3) rotation whose third column is the unit ``axis`` (local z maps to ``axis``)."""
    z = np.asarray(axis, dtype=np.float64)
    z = z / np.linalg.norm(z)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z], axis=1)


_FACES = {  # face name: (normal axis, sign, u axis, v axis) with u x v = sign * normal
    "+x": (0, 1, 1, 2), "-x": (0, -1, 2, 1),
    "+y": (1, 1, 2, 0), "-y": (1, -1, 0, 2),
    "+z": (2, 1, 0, 1), "-z": (2, -1, 1, 0),
}


def unit_box(counts: Sequence[int], skip: Sequence[str] = ()) -> Part:
    """Surface of the cube [-1, 1]^3 with ``counts[a]`` cells along axis ``a``, vertices welded.

    ``skip`` names faces to leave out (e.g. ``("-z",)`` gives an open-bottom box).
    Normals point outward.
    """
    parts = []
    for name, (axis, sign, ua, va) in _FACES.items():
        if name in skip:
            continue
        u = np.linspace(-1.0, 1.0, counts[ua] + 1)
        w = np.linspace(-1.0, 1.0, counts[va] + 1)
        uu, ww = np.meshgrid(u, w, indexing="ij")
        pts = np.zeros((uu.size, 3))
        pts[:, axis] = sign
        pts[:, ua], pts[:, va] = uu.ravel(), ww.ravel()
        parts.append((pts, grid_faces(len(u), len(w))))
    v, f = concat(parts)
    key = np.round(v * 1e6).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    return v[first], inverse.reshape(-1)[f]


def box(center: Sequence[float], half: Sequence[float], cell: float,
        skip: Sequence[str] = ()) -> Part:
    """Axis-aligned box of half sizes ``half`` (3,), subdivided into cells of about ``cell``."""
    half = np.asarray(half, dtype=np.float64)
    counts = np.maximum(1, np.ceil(2.0 * half / cell)).astype(int)
    v, f = unit_box(counts, skip)
    return v * half + np.asarray(center, dtype=np.float64), f


def superellipsoid(center: Sequence[float], half: Sequence[float], exponent: float,
                   cells: int = 16) -> Part:
    """Closed rounded box {|x/a|^p + |y/b|^p + |z/c|^p = 1}: p = 2 an ellipsoid, large p a box.

    The cube surface (``cells`` per side) is pushed radially onto the surface, so vertices stay
    well spread and the mesh is closed and outward-oriented.
    """
    v, f = unit_box((cells, cells, cells))
    scale = (np.abs(v) ** exponent).sum(axis=1) ** (1.0 / exponent)
    v = v / scale[:, None]
    return v * np.asarray(half, dtype=np.float64) + np.asarray(center, dtype=np.float64), f


def capped_tube(ring: np.ndarray) -> Part:
    """Close a tube given as rings (nv, nu, 3) (v along the axis, u around it) with two fans.

    Rings must run counter-clockwise about the axis direction (first ring to last); the result
    is closed and outward-oriented.
    """
    nv, nu, _ = ring.shape
    v = ring.transpose(1, 0, 2).reshape(-1, 3)  # index u * nv + j
    f = grid_faces(nu, nv, wrap_u=True)
    first, last = len(v), len(v) + 1
    v = np.concatenate([v, ring[0].mean(0, keepdims=True), ring[-1].mean(0, keepdims=True)])
    u = np.arange(nu)
    u1 = (u + 1) % nu
    bottom = np.stack([np.full(nu, first), u1 * nv, u * nv], 1)
    top = np.stack([np.full(nu, last), u * nv + nv - 1, u1 * nv + nv - 1], 1)
    return v, np.concatenate([f, bottom, top]).astype(np.int64)


def cylinder(p0: Sequence[float], p1: Sequence[float], radius: float,
             around: int = 24, along: int = 2) -> Part:
    """Closed cylinder from ``p0`` to ``p1`` (3,) of ``radius``."""
    p0, p1 = np.asarray(p0, dtype=np.float64), np.asarray(p1, dtype=np.float64)
    rot = frame_from_axis(p1 - p0)
    theta = np.linspace(0.0, 2.0 * np.pi, around, endpoint=False)
    t = np.linspace(0.0, 1.0, along)
    circle = np.stack([np.cos(theta), np.sin(theta), np.zeros_like(theta)], 1) * radius
    ring = p0 + t[:, None, None] * (p1 - p0) + (circle @ rot.T)[None]
    return capped_tube(ring)


def torus(center: Sequence[float], axis: Sequence[float], major: float, radial: float,
          axial: float, exponent: float = 2.0, around: int = 48, section: int = 16) -> Part:
    """Closed torus about ``axis`` with a super-elliptic cross-section (a tyre when boxy).

    major: radius of the centre circle; radial, axial: half sizes of the cross-section.
    """
    rot = frame_from_axis(axis)
    theta = np.linspace(0.0, 2.0 * np.pi, around, endpoint=False)
    phi = np.linspace(0.0, 2.0 * np.pi, section, endpoint=False)
    cp, sp = np.cos(phi), np.sin(phi)
    cp = np.sign(cp) * np.abs(cp) ** (2.0 / exponent)
    sp = np.sign(sp) * np.abs(sp) ** (2.0 / exponent)
    th, r_c = np.meshgrid(theta, major + radial * cp, indexing="ij")
    _, z = np.meshgrid(theta, axial * sp, indexing="ij")
    local = np.stack([r_c * np.cos(th), r_c * np.sin(th), z], -1).reshape(-1, 3)
    faces = grid_faces(around, section, wrap_u=True, wrap_v=True)  # d/dtheta x d/dphi: outward
    return local @ rot.T + np.asarray(center, dtype=np.float64), faces


def plane(origin: Sequence[float], edge_u: Sequence[float], edge_v: Sequence[float],
          cell: float) -> Part:
    """Single-sheet parallelogram ``origin + s * edge_u + t * edge_v``, s, t in [0, 1].

    The normal is edge_u x edge_v; subdivided into cells of about ``cell``.
    """
    eu, ev = np.asarray(edge_u, dtype=np.float64), np.asarray(edge_v, dtype=np.float64)
    nu = max(1, int(np.ceil(np.linalg.norm(eu) / cell))) + 1
    nv = max(1, int(np.ceil(np.linalg.norm(ev) / cell))) + 1
    s, t = np.meshgrid(np.linspace(0, 1, nu), np.linspace(0, 1, nv), indexing="ij")
    v = np.asarray(origin, dtype=np.float64) + s.reshape(-1, 1) * eu + t.reshape(-1, 1) * ev
    return v, grid_faces(nu, nv)


def oriented_outward(part: Part) -> Part:
    """Flip a closed part's faces if its signed volume is negative."""
    v, f = part
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0
    return (v, f) if volume >= 0 else (v, f[:, [0, 2, 1]])

