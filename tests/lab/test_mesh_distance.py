import numpy as np

from lab.training.mesh_distance import closest_points_on_triangles, point_mesh_distance


def _brute_force_closest(p, a, b, c, grid=400):
    """Closest of a dense barycentric grid of the triangle: accurate to ~edge / grid."""
    u, v = np.meshgrid(np.linspace(0, 1, grid), np.linspace(0, 1, grid), indexing="ij")
    keep = u + v <= 1
    u, v = u[keep], v[keep]
    pts = a + u[:, None] * (b - a) + v[:, None] * (c - a)
    return pts[np.argmin(np.linalg.norm(pts - p, axis=1))]


def test_closest_point_matches_a_dense_search_in_every_region():
    rng = np.random.default_rng(0)
    a, b, c = np.array([0.0, 0, 0]), np.array([1.0, 0, 0]), np.array([0.2, 0.9, 0])
    points = rng.uniform(-0.8, 1.8, (60, 3))  # vertex, edge and face regions all occur
    got = closest_points_on_triangles(points, *(np.tile(x, (60, 1)) for x in (a, b, c)))
    for p, q in zip(points, got):
        expected = _brute_force_closest(p, a, b, c)
        assert abs(np.linalg.norm(p - q) - np.linalg.norm(p - expected)) < 5e-3


def test_distance_to_a_triangulated_sphere_is_exact_on_its_faces():
    # An icosahedron: distances from points near a face centre are the plane distance.
    t = (1 + 5 ** 0.5) / 2
    v = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                  [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], float)
    f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9],
                  [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2],
                  [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
                  [8, 6, 7], [9, 8, 1]])
    tri = v[f]
    centre = tri.mean(axis=1)
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    offsets = np.array([0.01, -0.03, 0.05])
    queries = np.concatenate([centre + d * normal for d in offsets])
    got = point_mesh_distance(v, f, queries, np.random.default_rng(0), samples=20000)
    np.testing.assert_allclose(got, np.repeat(np.abs(offsets), len(f)), atol=1e-12)
