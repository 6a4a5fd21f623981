"""The torch optimisation (what a CUDA GPU runs) moves the cover exactly as the numpy one does.

Checked on the CPU build of torch: same iterations, same vertices up to float rounding.
"""

import numpy as np
import pytest

from engine.errors import InputError
from engine.meshing.extract import MeshingSettings, extract_surface
from engine.meshing.marching import double_cover
from engine.meshing.optimize import optimize_cover
from lab import analytic

torch = pytest.importorskip("torch")


@pytest.mark.parametrize("shape", [analytic.sphere(radius=0.6), analytic.disk(radius=0.6)],
                         ids=["sphere", "disk"])
def test_torch_and_numpy_optimisations_agree(shape):
    from engine.meshing.optimize_torch import optimize_cover_torch

    field = analytic.sample_grid(shape, (-1, -1, -1), (1, 1, 1), 48, exact=False)
    vertices, faces, iso, _, _ = double_cover(field)
    field.prepare(iso + 3 * field.spacing)
    want, want_stats = optimize_cover(vertices, faces, field, 120, 4.0, 0.05, 0.75)
    got, got_stats = optimize_cover_torch(vertices, faces, field, 120, 4.0, 0.05, 0.75,
                                          device="cpu")
    assert got_stats.iterations == want_stats.iterations
    moved = np.linalg.norm(want - vertices, axis=1).mean() / field.spacing
    difference = np.linalg.norm(got - want, axis=1) / field.spacing
    assert moved > 0.1  # the optimisation did something worth comparing
    assert difference.mean() < 1e-3 and difference.max() < 0.05
    assert got_stats.mean_distance == pytest.approx(want_stats.mean_distance, abs=1e-4)


def test_exact_fields_are_refused_by_the_torch_optimisation():
    from engine.meshing.optimize_torch import optimize_cover_torch

    field = analytic.sample_grid(analytic.sphere(), (-1, -1, -1), (1, 1, 1), 16)
    vertices, faces, _, _, _ = double_cover(field)
    with pytest.raises(ValueError, match="grid fields only"):
        optimize_cover_torch(vertices, faces, field, 4, device="cpu")


def test_a_cuda_request_without_a_gpu_is_refused_clearly():
    if torch.cuda.is_available():
        pytest.skip("this machine has a GPU")
    field = analytic.sample_grid(analytic.sphere(), (-1, -1, -1), (1, 1, 1), 16)
    with pytest.raises(InputError, match="cuda"):
        extract_surface(field, MeshingSettings(device="cuda"))


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")
def test_cuda_extraction_matches_the_cpu():
    field = analytic.sample_grid(analytic.torus(), (-1, -1, -1), (1, 1, 1), 64, exact=False)
    cpu = extract_surface(field, MeshingSettings(device="cpu"))
    gpu = extract_surface(field, MeshingSettings(device="cuda"))
    assert gpu.stats["optimize_device"] == "cuda"
    assert abs(len(gpu.mesh.faces) - len(cpu.mesh.faces)) <= 0.01 * len(cpu.mesh.faces)
    assert gpu.stats["mean_distance_voxels"] == pytest.approx(cpu.stats["mean_distance_voxels"],
                                                              abs=1e-3)
