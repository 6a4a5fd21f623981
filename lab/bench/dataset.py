"""The benchmark's data: seeded procedural shapes per domain, scan conditions, real meshes.

A test set is a list of seeds. ``make_shape(domain, seed)`` gives the exact ground-truth mesh in
the unit frame; ``make_input(gt, domain, condition, seed)`` gives the input cloud in the same
frame. Test and train seeds never overlap. Sampling, acceptance and noise draw from separate
random streams (``default_rng([seed, k])``), so e.g. the noisy input is the clean input plus noise.
"""

import os
from dataclasses import dataclass
from typing import Dict, List, Tuple, Union

import numpy as np

from engine.frame import UnitFrame
from engine.geometry import Mesh, PointCloud
from engine.sampling import sample_surface
from .scan import virtual_scan
from .shapes.cars import make_car
from .shapes.garments import make_garment
from .shapes.rooms import build_room, room_layout

DOMAINS = ("cars", "garments", "rooms")
REAL = "real"  # the bench's out-of-domain set: the meshes of REAL_SHAPES, by index

REAL_SHAPES = ("cgal/bunny00.off", "cgal/fandisk.off", "cgal/mushroom.off", "cgal/horizons.off",
               "cgal/elephant-with-holes.off", "cgal/ChineseDragon-10kv.off", "scans/owl.ply",
               "scans/plasticVase.ply", "rangemap/face000.ply", "misc/airplane.ply",
               "scans/blackVase.ply", "scans/birdBath.ply")
"""Paths under ``<shared>/data/real`` of the real meshes used as out-of-domain checks."""

_TEST_SEED_BASE = 1_000_000
_STREAM_SAMPLE, _STREAM_SCAN, _STREAM_NOISE, _STREAM_OUTLIER = 1, 2, 3, 4


@dataclass(frozen=True)
class ScanCondition:
    """How an input cloud is made from a ground-truth surface (lengths in the unit frame).

    count: points in the cloud; noise_sigma: std of isotropic Gaussian noise added to every point;
    outlier_fraction: share of points displaced by N(0, outlier_sigma) per axis and clamped to
    [-outlier_clamp, outlier_clamp].
    """

    name: str
    count: int
    noise_sigma: float = 0.0
    outlier_fraction: float = 0.0
    outlier_sigma: float = 0.1
    outlier_clamp: float = 0.52


CONDITIONS: Dict[str, ScanCondition] = {
    "clean": ScanCondition("clean", 50_000),
    "sparse": ScanCondition("sparse", 10_000),
    "noisy": ScanCondition("noisy", 50_000, noise_sigma=0.0025),
    "outliers": ScanCondition("outliers", 50_000, outlier_fraction=0.1),
}


def _check_domain(domain: str, real: bool = False) -> None:
    if domain not in DOMAINS and not (real and domain == REAL):
        names = DOMAINS + ((REAL,) if real else ())
        raise ValueError(f"unknown domain {domain!r}; choose one of {', '.join(names)}")


def test_seeds(domain: str, count: int = 100) -> List[int]:
    """Seeds of the test shapes of ``domain``: 1 000 000 + i, never a train seed; for ``real``,
    the indices of ``REAL_SHAPES`` (at most all of them)."""
    _check_domain(domain, real=True)
    if domain == REAL:
        return list(range(min(count, len(REAL_SHAPES))))
    return [_TEST_SEED_BASE + i for i in range(count)]


def train_seeds(domain: str, count: int = 40) -> List[int]:
    """Seeds of the training shapes of ``domain``: 0 .. count-1 (at most 1 000 000)."""
    _check_domain(domain)
    if count > _TEST_SEED_BASE:
        raise ValueError(f"at most {_TEST_SEED_BASE} train seeds")
    return list(range(count))


def to_unit_frame(mesh: Mesh) -> Mesh:
    """The mesh moved and scaled so its vertices' bounding box is centred with longest side 1."""
    frame = UnitFrame.from_points(mesh.vertices)
    return Mesh(frame.to_unit(mesh.vertices), np.asarray(mesh.faces, dtype=np.int64),
                mesh.normals, mesh.colors)


def make_shape(domain: str, seed: int) -> Mesh:
    """The exact ground-truth mesh of one procedural shape, in the unit frame.

    Returns
    -------
    Mesh
        vertices (V, 3) float64 in [-0.5, 0.5] (longest side exactly 1), faces (F, 3) int64;
        cars: closed overlapping parts; garments: open tubes and layers; rooms: one-sided sheets
        and furniture, z up; real: the ``seed``-th mesh of ``REAL_SHAPES``.
    """
    _check_domain(domain, real=True)
    if domain == REAL:
        return real_shape(seed)
    if domain == "cars":
        vertices, faces = make_car(seed)
    elif domain == "garments":
        vertices, faces = make_garment(seed)
    else:
        vertices, faces = build_room(room_layout(seed))
    return to_unit_frame(Mesh(vertices, faces))


def room_viewpoints(seed: int) -> np.ndarray:
    """The scanner positions (K, 3) of room ``seed``, in the unit frame of ``make_shape``.

    The room's bounding box is [0, Lx] x [0, Ly] x [0, H] by construction, so the frame is known
    from the layout without building the mesh.
    """
    layout = room_layout(seed)
    size = np.asarray(layout.size)
    return (layout.viewpoints - size / 2) / size.max()


def make_input(gt: Mesh, domain: str, condition: Union[str, ScanCondition],
               seed: int) -> PointCloud:
    """The input cloud for ``gt`` (from ``make_shape(domain, seed)``) under ``condition`` (a name
    in ``CONDITIONS`` or a condition of one's own, e.g. the selector's dense training scans).

    Cars, garments and real meshes: ``count`` area-uniform samples. Rooms: a virtual scan from the room's
    2-4 scanner positions (density falls off with distance, occluded parts are missing). Then
    Gaussian noise or outliers as the condition says.

    Returns
    -------
    PointCloud
        points (count, 3) float64 in the unit frame; normals (count, 3) float64, the normal of the
        face each point was sampled on (before noise; meaningless for outliers).
    """
    _check_domain(domain, real=True)
    spec = condition if isinstance(condition, ScanCondition) else CONDITIONS[condition]
    if domain == "rooms":
        rng = np.random.default_rng([seed, _STREAM_SCAN])
        points, normals = virtual_scan(gt, spec.count, rng, viewpoints=room_viewpoints(seed))
    else:
        rng = np.random.default_rng([seed, _STREAM_SAMPLE])
        points, normals, _ = sample_surface(gt.vertices, gt.faces, spec.count, rng)
    points = points.copy()
    if spec.noise_sigma > 0:
        noise = np.random.default_rng([seed, _STREAM_NOISE])
        points += noise.normal(0.0, spec.noise_sigma, points.shape)
    if spec.outlier_fraction > 0:
        rng = np.random.default_rng([seed, _STREAM_OUTLIER])
        how_many = int(round(spec.outlier_fraction * len(points)))
        chosen = rng.choice(len(points), how_many, replace=False)
        moved = points[chosen] + rng.normal(0.0, spec.outlier_sigma, (len(chosen), 3))
        points[chosen] = np.clip(moved, -spec.outlier_clamp, spec.outlier_clamp)
    return PointCloud(points, normals)


def crop_to_input(mesh: Mesh, points: np.ndarray, max_dist: float = 0.01,
                  normals: np.ndarray = None) -> Mesh:
    """The part of ``mesh`` that the input saw: the scored ground truth for scanned rooms.

    The faces near the input are split until no edge is longer than ``max_dist / 2``, then a face
    is kept when any of its corners, edge midpoints or centroid lies within ``max_dist`` (unit
    frame) of an input point, as the CAP-UDF / ScanNet protocols drop ground truth far from the
    scan. The split makes the crop follow the scan's own edge to within ``max_dist / 2`` whatever
    the mesh's cells (rooms: 8 cm cells, 0.013-0.023 in the unit frame). With ``normals`` (the
    scan's, one per point) only points of the face's own surface count, ``|cos| > 0.7`` between
    the point's normal and the face's, and the point lies in the face's plane, within
    ``max_dist / 4`` of it: the floor hidden under a cabinet, within ``max_dist`` of the
    cabinet's seen sides, and the underside of a board or a mattress lying on another, within
    ``max_dist`` of its seen top and facing the same way, are no surface the scan saw. Unused
    vertices are dropped.

    Parameters
    ----------
    mesh : the full ground truth
    points : (N, 3) the input cloud, same frame
    max_dist : distance threshold, same units
    normals : (N, 3) the input's normals, optional

    Returns
    -------
    Mesh with a subset of the (split) faces; vertices (V', 3), faces (F', 3) int64
    """
    from scipy.spatial import cKDTree

    points = np.asarray(points, dtype=np.float64)
    tree = cKDTree(points)
    v, f = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)
    f = f[_near(v, f, tree, max_dist)]  # a face far from every point has no part near one
    v, f = split_long_edges(v, f, max_dist / 2)
    f = f[_near(v, f, tree, max_dist, None if normals is None else np.asarray(normals))]
    used, inverse = np.unique(f, return_inverse=True)
    return Mesh(v[used], inverse.reshape(-1, 3).astype(np.int64))


_SAME_SURFACE_COS = 0.7
_SAME_SURFACE_OFFSET = 0.25  # of max_dist: a scan point's distance from the face's plane
_SAME_SURFACE_NEIGHBOURS = 8


def _near(v: np.ndarray, f: np.ndarray, tree, max_dist: float,
          normals: np.ndarray = None) -> np.ndarray:
    """Per face: one of its corners, edge midpoints or centroid lies within ``max_dist`` of a
    point (with ``normals``: of one of the 8 nearest points whose normal is the face's and which
    lies in the face's plane)."""
    from engine.cpu_threads import query_threads

    if len(f) == 0:
        return np.zeros(0, bool)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    centroid = (a + b + c) / 3
    reach = max_dist + np.sqrt(np.max([((p - centroid) ** 2).sum(axis=1) for p in
                                       (a, b, c, (a + b) / 2, (b + c) / 2, (c + a) / 2)], axis=0))
    dist, _ = tree.query(centroid, distance_upper_bound=float(reach.max()),
                         workers=query_threads())
    maybe = np.flatnonzero(dist <= reach)  # the centroid test prunes before the 7 probes
    keep = np.zeros(len(f), bool)
    k = 1 if normals is None else _SAME_SURFACE_NEIGHBOURS
    corner = a[maybe]
    face_normal = None
    if normals is not None:
        face_normal = np.cross(b - a, c - a)[maybe]
        face_normal /= np.maximum(np.linalg.norm(face_normal, axis=1, keepdims=True), 1e-300)
    near = np.zeros(len(maybe), bool)
    for dist, idx in _probe_neighbours(v, f[maybe], centroid[maybe], tree, max_dist, k):
        found = dist <= max_dist  # (F, probes, k)
        if normals is not None:
            nearest = np.where(found, idx, 0)
            found &= np.abs(np.einsum("fpkc,fc->fpk", normals[nearest],
                                      face_normal)) > _SAME_SURFACE_COS
            offset = np.einsum("fpkc,fc->fpk", tree.data[nearest] - corner[:, None, None],
                               face_normal)
            found &= np.abs(offset) < _SAME_SURFACE_OFFSET * max_dist
        near |= found.any(axis=(1, 2))
    keep[maybe] = near
    return keep


def _probe_neighbours(v: np.ndarray, f: np.ndarray, centroid: np.ndarray, tree,
                      max_dist: float, k: int):
    """The ``k`` nearest points within ``max_dist`` of each face's 7 probes: distances and
    indices, (F, 3, k) for its corners, (F, 3, k) for its edge midpoints, (F, 1, k) for its
    centroid. A corner or a midpoint shared by several faces is queried once (a shared edge's
    midpoint is the same sum either way)."""
    from engine.cpu_threads import query_threads

    def query(positions):
        dist, idx = tree.query(positions, k=k, distance_upper_bound=max_dist,
                               workers=query_threads())
        return dist.reshape(len(positions), k), idx.reshape(len(positions), k)

    corners, corner_of = np.unique(f, return_inverse=True)
    dist, idx = query(v[corners])
    corner_of = corner_of.reshape(-1, 3)
    yield dist[corner_of], idx[corner_of]
    ends = np.stack([f, np.roll(f, -1, axis=1)], axis=2)  # (F, 3, 2): ab, bc, ca
    low, high = ends.min(axis=2), ends.max(axis=2)
    keys, edge_of = np.unique(low * np.int64(len(v)) + high, return_inverse=True)
    dist, idx = query((v[keys // len(v)] + v[keys % len(v)]) / 2)
    edge_of = edge_of.reshape(-1, 3)
    yield dist[edge_of], idx[edge_of]
    dist, idx = query(centroid)
    yield dist[:, None], idx[:, None]


def split_long_edges(v: np.ndarray, f: np.ndarray, max_edge: float):
    """Split faces 1 -> 4 at their edge midpoints until no edge is longer than ``max_edge``.

    A face whose longest edge is too long is split at its three midpoints. A neighbour across
    one of its shorter edges may stay whole, so the result can have T-junctions: it keeps the
    area and the shape, which is what cropping and scoring need, not a watertight topology.
    Returns (vertices, faces), the old vertices first.
    """
    v, f = np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64)
    while len(f):
        corners = v[f]
        longest = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
        big = longest > max_edge
        if not big.any():
            break
        split = f[big]
        edges = np.sort(np.concatenate([split[:, [0, 1]], split[:, [1, 2]], split[:, [2, 0]]]),
                        axis=1)
        unique, inverse = np.unique(edges, axis=0, return_inverse=True)
        mids = len(v) + inverse.ravel().reshape(3, -1)
        v = np.concatenate([v, (v[unique[:, 0]] + v[unique[:, 1]]) / 2])
        a, b, c = split.T
        ab, bc, ca = mids
        f = np.concatenate([f[~big], np.stack([a, ab, ca], 1), np.stack([ab, b, bc], 1),
                            np.stack([ca, bc, c], 1), np.stack([ab, bc, ca], 1)])
    return v, f


def shared_dir() -> str:
    """The shared reference folder: ``$UDF_SHARED_DIR``, else ``shared`` beside the repository."""
    override = os.environ.get("UDF_SHARED_DIR")
    if override:
        return override
    repo = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    return os.path.join(os.path.dirname(repo), "shared")


def real_shapes() -> List[Tuple[str, Mesh]]:
    """The real meshes of ``REAL_SHAPES`` as (name, mesh in the unit frame), in that order.

    Raises ``FileNotFoundError`` naming the folder when the shared data is missing.
    """
    return [(os.path.splitext(os.path.basename(rel))[0], real_shape(index))
            for index, rel in enumerate(REAL_SHAPES)]


def real_shape(index: int) -> Mesh:
    """The ``index``-th mesh of ``REAL_SHAPES``, in the unit frame."""
    from engine.io import read_mesh

    root = os.path.join(shared_dir(), "data", "real")
    if not os.path.isdir(root):
        raise FileNotFoundError(f"real meshes not found in {root}; set UDF_SHARED_DIR")
    mesh = read_mesh(os.path.join(root, REAL_SHAPES[index]))
    return to_unit_frame(Mesh(mesh.vertices, mesh.faces))
