"""Gap filling (engine/gap_fill.py): a sparse scan's flat gaps closed, rims left where they are."""

import numpy as np
import pytest

from engine.field import compute_udf_band
from engine.meshing import MeshingSettings, extract_surface
from engine.settings import ReconstructSettings

WIDTH, DEPTH, LINE_GAP = 1.0, 0.64, 0.08  # a flat strip scanned along lines 10 spacings apart


def _line_scan(tilt: float = 0.3) -> np.ndarray:
    """A flat rectangle WIDTH x DEPTH scanned in lines along x, LINE_GAP apart, tilted about x."""
    x = np.linspace(0.0, WIDTH, 250)
    y = np.arange(0.0, DEPTH + 1e-9, LINE_GAP)
    xx, yy = np.meshgrid(x, y, indexing="ij")
    points = np.stack([xx.ravel(), yy.ravel() * np.cos(tilt), yy.ravel() * np.sin(tilt)], axis=1)
    return points + np.array([0.0, 0.01, 0.02])


def _area(mesh) -> float:
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    return 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]),
                                axis=1).sum()


def _mesh(points: np.ndarray, fill: bool):
    settings = ReconstructSettings(resolution=128, fill_gaps=fill)
    band = compute_udf_band(points, settings, udf_source="nearest")
    return band, extract_surface(band.grid, MeshingSettings(device="cpu")).mesh


@pytest.fixture(scope="module")
def scanned_strip():
    points = _line_scan()
    return points, _mesh(points, False), _mesh(points, True)


def test_gaps_between_scan_lines_are_closed(scanned_strip):
    _, (_, holed), (band, filled) = scanned_strip
    true_area = WIDTH * DEPTH
    assert band.stats["gap_nodes"] > 0
    assert _area(holed) < 0.8 * true_area  # the lines lie farther apart than the band reaches
    assert _area(filled) > 0.96 * true_area


def test_the_default_settings_fill_the_gaps():
    """A user who changes nothing gets the strip closed: the fill is on by default."""
    band = compute_udf_band(_line_scan(), ReconstructSettings(resolution=128),
                            udf_source="nearest")
    mesh = extract_surface(band.grid, MeshingSettings(device="cpu")).mesh
    assert band.stats["gap_nodes"] > 0
    assert _area(mesh) > 0.96 * WIDTH * DEPTH


def test_rims_do_not_grow(scanned_strip):
    """Past the strip's edges every point lies on one side: nothing is filled there."""
    points, _, (_, filled) = scanned_strip
    assert _area(filled) < 1.03 * WIDTH * DEPTH
    # every vertex lies over the rectangle, within a voxel and a half of its edges
    h = 1.0 / 128
    lo, hi = points.min(axis=0) - 1.5 * h, points.max(axis=0) + 1.5 * h
    vertices = np.asarray(filled.vertices)
    assert np.all((vertices >= lo) & (vertices <= hi))


def test_a_dense_cloud_is_left_as_it_is():
    rng = np.random.default_rng(0)
    points = rng.uniform(0.0, 1.0, (20000, 3)) * np.array([1.0, 1.0, 0.0])  # a dense square
    plain = compute_udf_band(points, ReconstructSettings(resolution=64), udf_source="nearest")
    filled = compute_udf_band(points, ReconstructSettings(resolution=64, fill_gaps=True),
                              udf_source="nearest")
    assert filled.stats["gap_nodes"] == 0
    a, b = plain.grid.band(), filled.grid.band()
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


def test_filling_repeats_exactly():
    points = _line_scan(0.5)[::2]
    settings = ReconstructSettings(resolution=96, fill_gaps=True)
    first = compute_udf_band(points, settings, udf_source="nearest").grid.band()
    second = compute_udf_band(points, settings, udf_source="nearest").grid.band()
    assert first[0].tobytes() == second[0].tobytes() and first[1].tobytes() == second[1].tobytes()


def test_tiles_fill_the_gaps_as_one_grid_does():
    from engine.reconstruct import reconstruct

    points = _line_scan()
    settings = dict(resolution=128, fill_gaps=True, outliers="keep", workers=1)
    whole = reconstruct(points, ReconstructSettings(**settings), udf_source="nearest").mesh
    tiled = reconstruct(points, ReconstructSettings(tile_cells=48, **settings),
                        udf_source="nearest").mesh
    area = WIDTH * DEPTH
    assert _area(whole) > 0.96 * area
    assert _area(tiled) == pytest.approx(_area(whole), rel=0.02)


def test_a_scan_with_gaps_is_told_that_the_fill_would_close_them():
    """The message names the option where the balls had to reach past the lines, and only
    while it is off; a densely sampled surface gets no such message."""
    from engine.reconstruct import reconstruct

    def told(points, fill):
        result = reconstruct(points, ReconstructSettings(resolution=128, device="cpu",
                                                         fill_gaps=fill))
        return any("Fill Gaps" in message for message in result.messages)

    assert told(_line_scan(), False) and not told(_line_scan(), True)
    rng = np.random.default_rng(0)
    dense = rng.uniform(0.0, 1.0, (20000, 3)) * np.array([1.0, 1.0, 0.0])
    assert not told(dense, False)


@pytest.mark.parametrize("count", [13, 20, 33])
def test_a_cloud_of_fewer_points_than_the_edge_test_reads_is_meshed(count):
    """The edge test reads 32 neighbours; a cloud of 13 to 33 points has fewer."""
    from engine.reconstruct import reconstruct

    rng = np.random.default_rng(count)
    points = np.column_stack([rng.random((count, 2)), np.zeros(count)])
    result = reconstruct(points, ReconstructSettings(resolution=32), udf_source="nearest")
    assert len(result.mesh.faces) > 0
    assert np.abs(result.mesh.vertices[:, 2]).max() < 2.0 / 32  # the plane, within 2 voxels


def test_the_compiled_edge_test_finds_the_numpy_edge_points(monkeypatch):
    from scipy.spatial import cKDTree

    from engine import gap_fill
    from engine.compiled import kernels

    assert kernels("gap_fill_kernels") is not None  # numba is a requirement
    rng = np.random.default_rng(1)
    # scan lines, a rim and scattered points: edge points of every kind
    points = np.vstack([_line_scan(), rng.random((3000, 3)) * [1.0, 0.6, 0.02]])
    tree = cKDTree(points)
    compiled = gap_fill._point_planes(tree, points, 6 / 128)
    monkeypatch.setenv("UDF_RECON_KERNELS", "numpy")
    numpy_path = gap_fill._point_planes(tree, points, 6 / 128)
    assert 100 < numpy_path[2].sum() < len(points) - 100
    for mine, theirs in zip(compiled, numpy_path):
        np.testing.assert_array_equal(mine, theirs)
