"""Tiled reconstruction: a cloud forced through small tiles comes out as it does in one grid."""

import os

import numpy as np
import pytest

from engine.meshing.mesh_ops import edge_topology, face_normals, vertex_components
from engine.reconstruct import reconstruct
from engine.tile_plan import CloudTiles

RESOLUTION = 64
TILE = 24


def hemisphere_cloud(count: int, seed: int = 0) -> np.ndarray:
    """Points on the upper half of a sphere of radius 0.5: an open surface with one rim."""
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(count, 3))
    v[:, 2] = np.abs(v[:, 2])
    return 0.5 * v / np.linalg.norm(v, axis=1, keepdims=True)


def surface_error(vertices: np.ndarray) -> np.ndarray:
    """Distance of mesh vertices to the true hemisphere (radius 0.5, z >= 0)."""
    r = np.linalg.norm(vertices, axis=1)
    on_sphere = np.abs(r - 0.5)
    below = vertices[:, 2] < 0  # past the rim: distance to the rim circle
    rho = np.linalg.norm(vertices[:, :2], axis=1)
    rim = np.hypot(rho - 0.5, vertices[:, 2])
    return np.where(below, rim, on_sphere)


def border_distance(vertices: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Distance (cells) of each vertex to the nearest inner tile border plane."""
    spacing = 1.0 / RESOLUTION
    extent = points.max(axis=0) - points.min(axis=0)
    unit = 1.0 / extent.max()  # the working frame of this cloud is the unit frame
    low = points.min(axis=0)
    size = TILE * spacing / unit
    counts = np.ceil((points.max(axis=0) - low) / size - 1e-9)
    r = (vertices - low) / size
    nearest = np.clip(np.round(r), 1, np.maximum(counts - 1, 1))
    gap = np.abs(r - nearest) * TILE
    gap[:, counts < 2] = np.inf
    return gap.min(axis=1)


@pytest.fixture(scope="module")
def meshes():
    cloud = hemisphere_cloud(20_000)
    settings = dict(detail="resolution", resolution=RESOLUTION, seed=0)
    whole = reconstruct(cloud, settings)
    tiled = reconstruct(cloud, dict(settings, tile_cells=TILE))
    return cloud, whole, tiled


def test_the_cloud_is_cut_into_several_tiles(meshes):
    cloud, whole, tiled = meshes
    assert "tiles" not in whole.stats
    unit = cloud / np.ptp(cloud, axis=0).max()
    assert tiled.stats["tiles"] == len(CloudTiles(unit, 1.0 / RESOLUTION, TILE, 0.0).tiles) >= 8


def test_tiles_match_one_grid(meshes):
    cloud, whole, tiled = meshes
    error_whole = surface_error(whole.mesh.vertices).mean()
    error_tiled = surface_error(tiled.mesh.vertices).mean()
    assert error_tiled < 1.02 * error_whole + 1e-5
    area = [np.linalg.norm(np.cross(m.vertices[m.faces[:, 1]] - m.vertices[m.faces[:, 0]],
                                    m.vertices[m.faces[:, 2]] - m.vertices[m.faces[:, 0]]),
                           axis=1).sum() / 2 for m in (whole.mesh, tiled.mesh)]
    assert abs(area[1] / area[0] - 1) < 0.01  # no face kept twice, no gap
    assert vertex_components(len(tiled.mesh.vertices), tiled.mesh.faces)[0] == 1


def test_no_seams_along_tile_borders(meshes):
    cloud, whole, tiled = meshes
    for result in (whole, tiled):
        topo = edge_topology(result.mesh.faces)
        result.rim_edges = topo.edges[topo.counts == 1]
        result.nonmanifold = topo.edges[topo.counts > 2]
    spacing = 0.5 * 2 / RESOLUTION  # the cloud spans 1 unit: one cell in its units

    def away_from_rim(mesh, edges):
        middle = mesh.vertices[edges].mean(axis=1)
        return middle[middle[:, 2] > 2 * spacing]

    # the only true boundary is the rim at z = 0: no boundary edge may run along a tile border
    assert len(away_from_rim(tiled.mesh, tiled.rim_edges)) <= len(
        away_from_rim(whole.mesh, whole.rim_edges))
    assert len(tiled.nonmanifold) <= len(whole.nonmanifold)
    assert tiled.stats["meshing"]["welded"] > 500


def test_the_surface_near_borders_is_as_good_as_away_from_them(meshes):
    cloud, _, tiled = meshes
    vertices = tiled.mesh.vertices
    near = border_distance(vertices, cloud) < 1.0
    assert near.sum() > 200 and (~near).sum() > 200
    within = surface_error(vertices) < 0.25 / RESOLUTION
    assert within[near].mean() > 0.98 * within[~near].mean()


@pytest.fixture(scope="module")
def small_tiled():
    cloud = hemisphere_cloud(8_000, seed=2)
    settings = dict(detail="resolution", resolution=48, tile_cells=24, seed=0)
    return cloud, settings, reconstruct(cloud, dict(settings, workers=1))


def test_two_workers_give_the_same_mesh_bit_for_bit(small_tiled):
    cloud, settings, one = small_tiled
    two = reconstruct(cloud, dict(settings, workers=2))
    assert one.stats["tiles"] >= 4 and two.stats["workers"] == 2
    assert one.stats["worker_processes"] == 0 and two.stats["worker_processes"] == 2
    assert np.array_equal(one.mesh.vertices, two.mesh.vertices)
    assert np.array_equal(one.mesh.faces, two.mesh.faces)


def test_the_tiles_meshes_wait_on_disk_and_the_folder_is_removed(small_tiled, monkeypatch,
                                                                  tmp_path):
    """Each tile's mesh is split as it reaches the main process: its seam held, the rest
    written to a temporary folder, which is gone once the mesh is made."""
    import tempfile

    from engine import tiles

    cloud, settings, one = small_tiled
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    split, stored = tiles.split_tile, []

    def spy(*args, **kwargs):
        piece = split(*args, **kwargs)
        stored.append(piece.rest.stored)
        assert os.path.getsize(piece.rest.stored) > 0
        return piece

    monkeypatch.setattr(tiles, "split_tile", spy)
    again = reconstruct(cloud, dict(settings, workers=1))
    assert len(stored) >= one.stats["tiles"]
    assert all(str(path).startswith(str(tmp_path)) for path in stored)
    assert list(tmp_path.iterdir()) == []
    assert np.array_equal(one.mesh.faces, again.mesh.faces)


def test_no_room_for_the_tiles_meshes_is_a_clear_error(monkeypatch):
    from engine.errors import InputError

    def full_disk(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez", full_disk)
    with pytest.raises(InputError, match="free some disk space there or set TMPDIR"):
        reconstruct(hemisphere_cloud(4_000), dict(detail="resolution", resolution=48,
                                                  tile_cells=24, workers=1))


def test_a_local_dask_cluster_gives_the_same_mesh(small_tiled):
    pytest.importorskip("distributed", reason="Dask is optional: pip install dask[distributed]")
    cloud, settings, one = small_tiled
    dask = reconstruct(cloud, dict(settings, workers=2, scheduler="local"))
    assert np.array_equal(one.mesh.vertices, dask.mesh.vertices)
    assert np.array_equal(one.mesh.faces, dask.mesh.faces)


def test_an_unreachable_scheduler_is_a_clear_error():
    pytest.importorskip("distributed", reason="Dask is optional: pip install dask[distributed]")
    from engine.errors import InputError

    cloud = hemisphere_cloud(4_000)
    with pytest.raises(InputError, match="could not reach the Dask scheduler"):
        reconstruct(cloud, dict(detail="resolution", resolution=32, tile_cells=24,
                                scheduler="tcp://127.0.0.1:9"))


@pytest.mark.parametrize("mode", ["curvature", "learned"])
def test_every_radius_mode_runs_in_tiles(mode):
    cloud = hemisphere_cloud(8_000, seed=3)
    settings = dict(detail="resolution", resolution=48, radius_mode=mode, workers=1)
    whole = reconstruct(cloud, settings)
    tiled = reconstruct(cloud, dict(settings, tile_cells=24))
    assert tiled.stats["tiles"] >= 4
    assert surface_error(tiled.mesh.vertices).mean() < 1.05 * surface_error(
        whole.mesh.vertices).mean() + 1e-5


@pytest.mark.parametrize("workers", [1, 2])
def test_cancel_stops_between_and_during_tiles(workers):
    import time

    from engine.errors import Cancelled

    cloud = hemisphere_cloud(8_000, seed=4)
    seen = []

    def progress(fraction, message):
        seen.append((fraction, message))

    def cancel():
        return any("tile" in message and fraction > 0.2 for fraction, message in seen)

    started = time.perf_counter()
    with pytest.raises(Cancelled):
        reconstruct(cloud, dict(detail="resolution", resolution=48, tile_cells=24,
                                workers=workers), progress=progress, cancel=cancel)
    # stopped well before the tiles were all made (a full run takes several times longer)
    assert max(f for f, _ in seen) < 0.9
    assert time.perf_counter() - started < 60


def _grid_sheet(x0, x1, y1, step):
    """A flat triangulated sheet on z = 0 over [x0, x1] x [0, y1], normals +z."""
    xs, ys = np.arange(x0, x1 + 1e-9, step), np.arange(0.0, y1 + 1e-9, step)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    vertices = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    index = np.arange(gx.size).reshape(gx.shape)
    a, b = index[:-1, :-1].ravel(), index[1:, :-1].ravel()
    c, d = index[1:, 1:].ravel(), index[:-1, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return vertices, faces


def test_a_tile_that_kept_the_other_side_is_found_and_the_seam_welds():
    from engine.tile_plan import Tile
    from engine.tiles import stitch, tiles_to_turn

    step = 1.0 / 64
    left = _grid_sheet(-1.0, 0.0, 1.0, step)
    right = _grid_sheet(0.0, 0.5, 1.0, step)  # the smaller piece ...
    right = (right[0], right[1][:, ::-1])       # ... faces the other way
    inf = np.full(3, np.inf)
    tiles = [Tile((0, 0, 0), -inf, np.array([0.0, np.inf, np.inf])),
             Tile((1, 0, 0), np.array([0.0, -np.inf, -np.inf]), inf)]
    assert list(tiles_to_turn([left, right], tiles, step)) == [1]
    vertices, faces, stats = stitch([left, right], tiles, step)
    assert stats["flipped"] == 1
    topo = edge_topology(faces)
    middle = vertices[topo.edges[topo.counts == 1]].mean(axis=1)
    assert not np.any(np.abs(middle[:, 0]) < 0.5 * step)  # no boundary left along x = 0
    assert (topo.counts <= 2).all()


def _punch(sheet, x_from, step):
    """The sheet without a 3 x 3 block of its squares (a hole of 12 edges) starting at x_from,
    its vertices lifted off the plane a little (a fan over a hole with collinear sides would
    have faces of no area)."""
    vertices, faces = sheet
    vertices = vertices.copy()
    vertices[:, 2] = 0.1 * step * np.sin(vertices[:, 0] * 517.0 + vertices[:, 1] * 311.0)
    centre = vertices[faces].mean(axis=1)
    hole = ((centre[:, 0] > x_from) & (centre[:, 0] < x_from + 3 * step)
            & (centre[:, 1] > 0.5) & (centre[:, 1] < 0.5 + 3 * step))
    return vertices, faces[~hole]


def test_only_the_seam_is_stitched():
    """A hole at the border is closed, one deep inside a tile is left as its mesher made it,
    and the faces away from the border come out as they went in."""
    from engine.tile_plan import Tile
    from engine.tiles import SEAM_CELLS, stitch

    step = 1.0 / 64
    left = _punch(_grid_sheet(-1.0, 0.0, 1.0, step), -0.5, step)             # deep inside
    right = _punch(_grid_sheet(0.0, 1.0, 1.0, step), 1e-9, step)  # at the border
    inf = np.full(3, np.inf)
    tiles = [Tile((0, 0, 0), -inf, np.array([0.0, np.inf, np.inf])),
             Tile((1, 0, 0), np.array([0.0, -np.inf, -np.inf]), inf)]
    given = [left, right]
    vertices, faces, stats = stitch(given, tiles, step)
    assert given == []  # the stitcher frees each tile's arrays once it has read them
    assert stats["holes_closed"] == 1
    topo = edge_topology(faces)
    rim = vertices[topo.edges[topo.counts == 1]].mean(axis=1)
    inner = (np.abs(rim[:, 0]) < 1 - step / 4) & (rim[:, 1] > step / 4) & (rim[:, 1] < 1 - step / 4)
    assert inner.sum() == 12
    assert np.all(np.abs(rim[inner, 0] + 0.5) < 4 * step)  # the hole deep inside stays open
    far = faces[np.abs(vertices[faces].mean(axis=1)[:, 0]) > (SEAM_CELLS + 1) * step]
    before = np.concatenate([v[f] for v, f in (left, right)])
    after = vertices[far]
    key = lambda corners: set(map(tuple, np.round(corners.reshape(len(corners), -1), 12)))
    assert key(after) <= key(before)


def test_tiles_cut_axis_aligned_walls_into_as_few_faces_as_one_grid():
    """An open box whose walls lie a whole number of cells from its lowest point: the tiles'
    nodes must not sit on the walls (marching cubes then cuts them into slivers, a third more
    faces for the same area)."""
    rng = np.random.default_rng(0)
    dims = np.array([1.0, 0.8037, 0.6123])
    parts = []
    for axis in range(3):
        for side in (0.0, 1.0):
            if axis == 2 and side == 1.0:
                continue
            wall = rng.random((4_000, 3)) * dims
            wall[:, axis] = side * dims[axis]
            parts.append(wall)
    cloud = np.concatenate(parts)
    settings = dict(detail="resolution", resolution=48, seed=0, workers=1)
    whole = reconstruct(cloud, settings).mesh
    tiled = reconstruct(cloud, dict(settings, tile_cells=24)).mesh
    area = [face_normals(mesh.vertices, mesh.faces)[1].sum() for mesh in (whole, tiled)]
    assert abs(area[1] / area[0] - 1.0) < 0.01
    assert len(tiled.faces) < 1.05 * len(whole.faces), (len(tiled.faces), len(whole.faces))


def test_the_turn_votes_gathered_tile_by_tile_are_those_of_all_seams_at_once(monkeypatch):
    """Each tile's window (itself and its neighbours) finds exactly the weld pairs, and their
    votes, that the seams of all tiles joined give."""
    from engine import tiles as tiling

    captured = []
    stitched_in_blocks = tiling.stitched_in_blocks

    def capture(pieces, tile_list, spacing, min_component_faces=0, folder=None):
        held = tiling._split_all(list(pieces), tile_list, spacing, hold=True)
        captured.append((held, tile_list, spacing))
        return stitched_in_blocks(pieces, tile_list, spacing, min_component_faces, folder)

    monkeypatch.setattr(tiling, "stitched_in_blocks", capture)
    reconstruct(hemisphere_cloud(8_000, seed=3),
                dict(detail="resolution", resolution=80, tile_cells=24, workers=1))
    pieces, tile_list, spacing = captured[-1]
    assert len(tile_list) >= 12
    seam = tiling._seam(pieces, spacing)
    agree = tiling._pair_agreement(seam.points, seam.faces, seam.a, seam.b)
    piece = tiling._vertex_pieces(len(seam.points), seam.faces, seam.face_piece)
    whole = sorted(zip(np.minimum(piece[seam.a], piece[seam.b]).tolist(),
                       np.maximum(piece[seam.a], piece[seam.b]).tolist(), agree.tolist()))
    piece_first = np.cumsum([0] + [len(p.piece_area) for p in pieces])
    number_of = {tile.index: number for number, tile in enumerate(tile_list)}
    windowed = []
    for number, tile in enumerate(tile_list):
        window = sorted({number_of[n] for n in tiling._around(tile.index) if n in number_of})
        pa, pb, votes = tiling._tile_votes(pieces, piece_first, window, number, spacing)
        windowed += zip(np.minimum(pa, pb).tolist(), np.maximum(pa, pb).tolist(), votes.tolist())
    assert len(whole) > 100
    assert sorted(windowed) == whole
