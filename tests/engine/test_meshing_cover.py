"""The double cover: exact index→world map, closedness, iso choice."""

import numpy as np
import pytest

from engine.errors import InputError
from engine.meshing import marching
from engine.meshing import mesh_ops as mo
from lab import analytic as A

CENTER = np.array([0.3, -0.2, 0.7])


def off_centre_sphere_grid():
    """A sphere in a non-cubic box whose centre is not the sphere's."""
    shape = A.sphere(CENTER, 0.3)
    return shape, A.sample_grid(shape, CENTER - [0.4, 0.45, 0.5], CENTER + [0.45, 0.4, 0.38],
                                80, exact=False)


def test_mapping_exact_on_non_cubic_box():
    _, grid = off_centre_sphere_grid()
    assert len(set(grid.shape)) > 1
    h = grid.spacing
    verts, faces = marching.marching_cover(grid, h)
    r = np.linalg.norm(verts - CENTER, axis=1)
    outer = r > 0.3
    assert np.abs(r[outer] - (0.3 + h)).max() < 0.05 * h
    assert np.abs(r[~outer] - (0.3 - h)).max() < 0.05 * h


@pytest.mark.parametrize("slab", [64, 9])
def test_cover_closed_two_shells(slab):
    _, grid = off_centre_sphere_grid()
    verts, faces = marching.marching_cover(grid, grid.spacing, slab=slab)
    topo = mo.edge_topology(faces)
    assert np.all(topo.counts == 2)  # closed, edge-manifold, slabs welded
    assert mo.orientation_consistent(faces)
    pairs, _ = mo.dual_edges(faces, topo)
    count, labels = mo.face_components(len(faces), pairs)
    assert count == 2
    vols = sorted(mo.signed_volume(verts, faces[labels == k]) for k in range(2))
    assert vols[0] < 0 < vols[1]  # normals point away from the surface on both shells
    for k in range(2):
        assert mo.euler_characteristic(faces[labels == k]) == 2


def test_disk_cover_is_one_sphere_like_pancake():
    grid = A.sample_grid(A.disk((0, 0, 0), 0.3), [-0.5] * 3, [0.5] * 3, 64, exact=False)
    verts, faces = marching.marching_cover(grid, 0.6 * grid.spacing)
    report = marching.cover_report(faces)
    assert report.components == 1 and report.handles == 0 and not report.fragmented


def test_small_iso_fragments_and_auto_iso_recovers():
    _, grid = off_centre_sphere_grid()
    _, faces = marching.marching_cover(grid, 0.3 * grid.spacing)
    assert marching.cover_report(faces).fragmented
    _, faces, iso, report, messages = marching.double_cover(grid, 0.3 * grid.spacing)
    assert messages  # a given iso is kept but the user is warned
    _, faces, iso, report, _ = marching.double_cover(grid, None)
    assert report.components == 2 and iso == pytest.approx(grid.spacing)


def test_auto_iso_lifts_above_noise_floor():
    shape = A.sphere((0, 0, 0), 0.3)
    grid = A.sample_grid(shape, [-0.5] * 3, [0.5] * 3, 48, exact=False)
    h = grid.spacing
    noisy = grid.slab(0, grid.shape[0]) + np.float32(1.2 * h)  # a field that never reaches 0
    from engine.meshing import UDFGrid
    grid = UDFGrid(noisy, grid.origin, h)
    _, faces, iso, report, _ = marching.double_cover(grid, None)
    assert iso > 1.2 * h and report.components == 2


def test_iso_below_field_refused():
    _, grid = off_centre_sphere_grid()
    with pytest.raises(InputError):
        marching.double_cover(grid, 0.5 * grid.min_value if grid.min_value > 0 else 1e-9)
