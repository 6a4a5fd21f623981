"""Reconstructing straight into a file: a tiled mesh goes to PLY tile by tile, byte for byte
what the in-memory mesh writes, and a refused or cancelled write leaves the target alone."""

import hashlib

import numpy as np
import pytest

import engine.tiles
from engine.errors import Cancelled, InputError
from engine.geometry import Mesh, PointCloud
from engine.io import read_mesh, write_mesh, write_ply_in_blocks
from engine.meshing.mesh_ops import vertex_components
from engine.reconstruct import reconstruct
from engine.reconstruct_to_file import reconstruct_to_file

from .test_tiles import hemisphere_cloud

SETTINGS = dict(detail="resolution", resolution=48, tile_cells=24, seed=0, workers=1)


def digest(path) -> str:
    return hashlib.md5(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def coloured():
    points = hemisphere_cloud(8_000, seed=3)
    colors = np.random.default_rng(3).random((len(points), 3)).astype(np.float32)
    cloud = PointCloud(points, colors=colors)
    return cloud, reconstruct(cloud, SETTINGS)


def test_a_tiled_ply_is_streamed_with_the_same_bytes_as_the_mesh_in_memory(coloured, tmp_path):
    cloud, in_memory = coloured
    assert in_memory.stats["tiles"] > 1
    write_mesh(tmp_path / "whole.ply", in_memory.mesh)
    streamed = reconstruct_to_file(cloud, tmp_path / "streamed.ply", SETTINGS)
    assert streamed.mesh is None, "the tiled mesh went to the file, not to memory"
    assert digest(tmp_path / "streamed.ply") == digest(tmp_path / "whole.ply")
    for key in ("vertices", "faces", "components"):
        assert streamed.stats[key] == in_memory.stats[key], key
    mesh = read_mesh(tmp_path / "streamed.ply")
    assert mesh.colors is not None and len(mesh.faces) == in_memory.stats["faces"]


def test_other_formats_and_one_grid_are_written_from_memory(coloured, tmp_path):
    cloud, in_memory = coloured
    result = reconstruct_to_file(cloud, tmp_path / "mesh.obj", SETTINGS)
    assert result.mesh is not None
    assert len(read_mesh(tmp_path / "mesh.obj").faces) == in_memory.stats["faces"]
    untiled = reconstruct_to_file(cloud.points, tmp_path / "one.ply",
                                  dict(SETTINGS, tile_cells=0))
    assert untiled.mesh is not None and "tiles" not in untiled.stats
    assert len(read_mesh(tmp_path / "one.ply").faces) == untiled.stats["faces"]


def test_a_cancel_while_the_tiles_are_written_leaves_the_previous_file(coloured, tmp_path):
    cloud, _ = coloured
    target = tmp_path / "mesh.ply"
    write_mesh(target, Mesh(np.eye(3), np.array([[0, 1, 2]])))
    before = digest(target)
    writing = []

    def progress(fraction, message):
        if message.startswith("writing"):
            writing.append(fraction)

    with pytest.raises(Cancelled):
        reconstruct_to_file(cloud, target, SETTINGS, progress, cancel=lambda: bool(writing))
    assert writing, "the write was under way"
    assert digest(target) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mesh.ply"]


def test_a_block_writer_that_refuses_at_the_end_writes_nothing(tmp_path):
    target = tmp_path / "mesh.ply"
    write_mesh(target, Mesh(np.eye(3), np.array([[0, 1, 2]])))
    before = digest(target)

    def faces():
        yield np.array([[0, 1, 2]])
        raise InputError("only specks")

    with pytest.raises(InputError, match="only specks"):
        write_ply_in_blocks(target, 3, 1, 0, [(np.eye(3), None)], faces())
    assert digest(target) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mesh.ply"]


def test_pieces_counted_tile_by_tile_match_the_whole_mesh(monkeypatch):
    """The writer counts a tiled mesh's pieces without holding it (each tile's rest faces in
    their own pieces, joined through the seam): the count and the largest piece's faces of the
    whole mesh gathered in memory."""
    from engine import tiles as tiling

    made = []
    stitched_in_blocks = tiling.stitched_in_blocks

    def counted(*args, **kwargs):
        stitched, stats = stitched_in_blocks(*args, **kwargs)
        vertices, faces = stitched.arrays()
        count, labels = vertex_components(len(vertices), faces)
        largest = int(np.bincount(labels).max())
        made.append((stitched.piece_sizes(), (count, largest)))
        return stitched, stats

    rng = np.random.default_rng(5)
    blobs = np.concatenate([hemisphere_cloud(20_000, seed=6)]
                           + [rng.normal(centre, 0.01, (400, 3))
                              for centre in rng.uniform(-0.4, 0.4, (12, 3))])
    monkeypatch.setattr(tiling, "stitched_in_blocks", counted)
    reconstruct(blobs, dict(SETTINGS, resolution=96, tile_cells=24, udf_source="nearest",
                            outliers="keep", min_component_faces=0))
    (pieces, whole), = made
    assert whole[0] > 5, "several pieces, of several sizes"
    assert pieces == whole


def test_the_tile_by_tile_write_never_holds_the_whole_mesh(tmp_path, monkeypatch):
    """numpy's allocations (tracemalloc) while the tiles are written: under half the mesh's
    arrays, which gathering the same stitched mesh into memory allocates. (The writer holds one
    block of tiles at a time: small tiles, so that a block is a small share of the mesh.)"""
    import tracemalloc

    import engine.reconstruct_to_file as to_file

    points = hemisphere_cloud(30_000, seed=4)
    cloud = PointCloud(points, colors=np.random.default_rng(4).random((len(points), 3)))
    settings = dict(SETTINGS, resolution=128, tile_cells=24, udf_source="nearest")
    real = to_file._write_stitched
    peaks = {}

    def peak(call):
        tracemalloc.start()
        try:
            return call()
        finally:
            peaks.setdefault(len(peaks), tracemalloc.get_traced_memory()[1])
            tracemalloc.stop()

    def measured(path, stitched, *rest):
        written = peak(lambda: real(path, stitched, *rest))
        gathered = peak(stitched.arrays)
        peaks["whole"] = sum(array.nbytes for array in gathered)
        return written

    monkeypatch.setattr(to_file, "_write_stitched", measured)
    monkeypatch.setattr(engine.tiles, "SEAM_BLOCK", 4096)  # as a large scan's share of it
    result = reconstruct_to_file(cloud, tmp_path / "mesh.ply", settings)
    assert result.stats["tiles"] >= 8
    assert peaks[1] > peaks["whole"], "gathering holds the whole mesh"
    assert peaks[0] < 0.5 * peaks["whole"], peaks
