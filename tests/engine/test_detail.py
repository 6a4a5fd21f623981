"""Detail in world units: the cell size from the settings, and balls that follow the cells."""

import argparse

import numpy as np
import pytest
from scipy.spatial import cKDTree

from engine.commands.settings_args import add_settings_arguments
from engine.detail import AUTO_MAX_CELLS, MAX_CELLS, MAX_TILED_CELLS, cell_size, choose_detail
from engine.errors import InputError
from engine.frame import UnitFrame
from engine.reconstruct import reconstruct
from engine.settings import ReconstructSettings
from engine.tiles import AUTO_TILE_CELLS, tile_size


def sphere_cloud(count: int, center=(0.0, 0.0, 0.0), radius: float = 0.5, seed: int = 0):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(count, 3))
    return np.asarray(center) + radius * v / np.linalg.norm(v, axis=1, keepdims=True)


def test_auto_is_the_unit_frame_up_to_50k_points():
    points = sphere_cloud(50_000) * 7.0 + 3.0
    detail = choose_detail(points, ReconstructSettings())
    unit = UnitFrame.from_points(points)
    assert detail.cells == 256 and not detail.capped
    assert detail.frame.scale == unit.scale  # bit for bit: today's results are unchanged
    assert np.array_equal(detail.frame.center, unit.center)


def test_auto_cells_follow_the_point_count():
    settings = ReconstructSettings()
    voxel, cells, capped = cell_size(200_000, 10.0, settings)
    assert cells == pytest.approx(512) and voxel == pytest.approx(10.0 / 512) and not capped
    voxel, cells, capped = cell_size(5_000_000, 10.0, settings)
    assert cells == AUTO_MAX_CELLS and capped
    voxel, cells, _ = cell_size(5_000_000, 10.0, ReconstructSettings(detail="resolution"))
    assert cells == 256


def test_too_fine_a_voxel_size_is_refused_with_the_size_that_works():
    points = sphere_cloud(1000) * 10_000.0
    with pytest.raises(InputError, match="raise the voxel size to at least") as refused:
        choose_detail(points, ReconstructSettings(detail="voxel_size", voxel_size=0.01))
    suggested = float(str(refused.value).rsplit(" ", 1)[1])
    detail = choose_detail(points, ReconstructSettings(detail="voxel_size",
                                                       voxel_size=suggested))
    assert MAX_TILED_CELLS * 0.995 < detail.cells <= MAX_TILED_CELLS


def test_a_scan_larger_than_one_grid_is_made_in_tiles_of_at_most_one_grid():
    """More cells than one grid may have are fine in tiles (automatic ones of 192 cells, or
    tiles asked up to MAX_CELLS); tiles asked larger than one grid are refused."""
    points = sphere_cloud(1000) * 50.0  # 50 units across: 5,000 cells at 0.01
    settings = dict(detail="voxel_size", voxel_size=0.01)
    detail = choose_detail(points, ReconstructSettings(**settings))
    assert detail.cells > 2 * MAX_CELLS
    assert tile_size(detail, ReconstructSettings(**settings)) == AUTO_TILE_CELLS
    choose_detail(points, ReconstructSettings(**settings, tile_cells=MAX_CELLS))
    with pytest.raises(InputError, match="set tile cells to at most 2,048"):
        choose_detail(points, ReconstructSettings(**settings, tile_cells=MAX_CELLS + 1))


def test_voxel_size_flag_sets_the_detail():
    parser = argparse.ArgumentParser()
    add_settings_arguments(parser)
    assert parser.parse_args([]).detail == "auto"
    args = parser.parse_args(["--voxel-size", "0.02"])
    assert (args.detail, args.voxel_size) == ("voxel_size", 0.02)
    args = parser.parse_args(["--detail", "resolution", "--voxel-size", "0.02"])
    assert args.detail == "resolution"


def _part(mesh, center, reach):
    """Faces of ``mesh`` whose centroid lies within ``reach`` of ``center``."""
    cents = mesh.vertices[mesh.faces].mean(axis=1)
    return mesh.faces[np.linalg.norm(cents - center, axis=1) < reach]


def test_a_larger_scene_keeps_the_detail_per_square_metre():
    """One sphere, then the same sphere with a copy 3 diameters away: with a voxel size the
    first sphere comes out the same in both; with a fixed resolution it coarsens."""
    one = sphere_cloud(6000)
    two = np.concatenate([one, sphere_cloud(6000, center=(3.0, 0.0, 0.0), seed=1)])
    settings = dict(detail="voxel_size", voxel_size=1 / 48, resolution=48, seed=0)
    alone = reconstruct(one, settings)
    beside = reconstruct(two, settings)
    assert alone.stats["cells"] == pytest.approx(48, rel=0.01)
    assert beside.stats["cells"] == pytest.approx(4 * 48, rel=0.01)
    # the ball covers as many cells in both
    for result in (alone, beside):
        assert result.stats["band_radius"] / result.stats["spacing"] == pytest.approx(
            alone.stats["band_radius"] / alone.stats["spacing"])
    faces_alone = len(alone.mesh.faces)
    faces_beside = len(_part(beside.mesh, np.zeros(3), 0.75))
    assert abs(faces_beside / faces_alone - 1.0) < 0.03
    gap, _ = cKDTree(alone.mesh.vertices).query(beside.mesh.vertices[
        np.linalg.norm(beside.mesh.vertices, axis=1) < 0.75])
    assert np.quantile(gap, 0.99) < 0.5 / 48  # vertices a cell apart: within half a cell
    # the box's resolution instead: the same 48 cells now span both spheres
    coarse = reconstruct(two, dict(settings, detail="resolution"))
    assert len(_part(coarse.mesh, np.zeros(3), 0.75)) < 0.2 * faces_alone
