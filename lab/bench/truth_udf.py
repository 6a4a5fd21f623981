"""``truth-udf``: our mesher on the true distance to the ground truth, the mesher's own floor.

``ours`` asks the network for the distance at the grid nodes near the points; this method puts
the ground truth's exact distance at the same nodes and meshes them with the same settings. What
it loses (area, layers, rims) is the mesher's at that grid, whatever the network does; the gap
between its row and ``ours`` is the network's.

The distance of a node is read off a dense sample of the truth's surface (``SAMPLES_PER_VOXEL``
per voxel of area, and along the rims four times as densely): to the nearest sample's tangent
plane where the node lies over that sample (its offset along the plane within twice the
samples' spacing), to the sample itself elsewhere (past a rim); the least over the ``NEAREST``
nearest samples. On a flat sheet and past its rim it is exact to
well under a hundredth of a voxel.
"""

import numpy as np

from engine.geometry import Mesh, PointCloud

SAMPLES_PER_VOXEL = 40  # surface samples per voxel^2 of the truth's area
NEAREST = 4  # samples asked per node


def truth_distances(surface: Mesh, nodes: np.ndarray, spacing: float, seed: int = 0):
    """Unsigned distances (float32, same units) from ``nodes`` (P, 3) to the mesh ``surface``."""
    from scipy.spatial import cKDTree

    from engine.meshing.mesh_ops import edge_topology
    from engine.sampling import face_areas_and_normals, sample_surface

    vertices = np.asarray(surface.vertices, np.float64)
    faces = np.asarray(surface.faces, np.int64).reshape(-1, 3)
    areas, normals = face_areas_and_normals(vertices, faces)
    count = int(np.ceil(areas.sum() / spacing ** 2 * SAMPLES_PER_VOXEL))
    samples, _, which = sample_surface(vertices, faces, count, np.random.default_rng(seed))
    gap = spacing / np.sqrt(SAMPLES_PER_VOXEL)  # the samples' mean spacing
    # the rims, more densely: a node past a rim is as far as its closest rim point
    topo = edge_topology(faces)
    rim = topo.counts == 1
    ends = vertices[topo.edges[rim]]
    steps = np.maximum(np.ceil(np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1) / (0.25 * gap)),
                       1).astype(np.int64)
    edge = np.repeat(np.arange(len(ends)), steps)
    t = (np.arange(steps.sum()) - np.repeat(np.cumsum(steps) - steps, steps)) / steps[edge]
    samples = np.r_[samples, ends[edge, 0] + t[:, None] * (ends[edge, 1] - ends[edge, 0])]
    which = np.r_[which, _edge_faces(topo, faces)[rim][edge]]
    distance, nearest = cKDTree(samples).query(nodes, k=NEAREST, workers=-1)
    offset = nodes[:, None, :] - samples[nearest]
    across = np.abs(np.einsum("ikj,ikj->ik", offset, normals[which[nearest]]))
    along = np.sqrt(np.maximum(distance ** 2 - across ** 2, 0.0))
    return np.where(along <= 2 * gap, across, distance).min(axis=1).astype(np.float32)


def _edge_faces(topo, faces: np.ndarray) -> np.ndarray:
    """A face of every edge of ``topo``."""
    owner = np.zeros(len(topo.counts), np.int64)
    owner[topo.face_edges.reshape(-1)] = np.repeat(np.arange(len(faces)), 3)
    return owner


def make_truth_udf(resolution: int = 256, device: str = "auto", fill_gaps: bool = False,
                   **settings):
    """The method ``(cloud, ground truth) -> Mesh``: the band and mesher of ``ours`` (fixed
    radius) on the truth's distances."""
    from engine.field import compute_udf_band
    from engine.frame import validate_points
    from engine.detail import choose_detail
    from engine.meshing import extract_surface
    from engine.reconstruct import meshing_settings
    from engine.settings import ReconstructSettings
    from engine.udf_grid import UDFGrid

    config = ReconstructSettings(radius_mode="fixed", resolution=resolution, device=device,
                                 fill_gaps=fill_gaps, **settings).validate()

    def truth_udf(cloud: PointCloud, gt: Mesh) -> Mesh:
        points = validate_points(cloud.points)
        frame = choose_detail(points, config).frame
        band = compute_udf_band(frame.to_unit(points), config, udf_source="nearest").grid
        nodes, _ = band.band()
        unit_truth = Mesh(frame.to_unit(np.asarray(gt.vertices, np.float64)),
                          np.asarray(gt.faces))
        values = truth_distances(unit_truth, band.index_to_world(nodes), band.spacing)
        grid = UDFGrid.from_band(nodes, values, band.shape, band.origin, band.spacing,
                                 band.far_value)
        mesh = extract_surface(grid, meshing_settings(config)).mesh
        return Mesh(frame.from_unit(np.asarray(mesh.vertices)), np.asarray(mesh.faces))

    truth_udf.__name__ = "truth-udf"
    truth_udf.needs_ground_truth = True
    return truth_udf
