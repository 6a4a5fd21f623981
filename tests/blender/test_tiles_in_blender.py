"""Tiles inside Blender: worker processes import the extension's engine without Blender, give the
same mesh as Blender's own process, and the tiles are made here when the workers cannot start."""

import numpy as np
import pytest

from tests.blender.helpers import sphere_points

SETTINGS = dict(detail="resolution", resolution=48, tile_cells=24, seed=0)


@pytest.fixture(scope="module")
def made_here(extension):
    reconstruct = extension.module("engine.reconstruct").reconstruct
    cloud = sphere_points(8_000, 0.8)
    return cloud, reconstruct(cloud, dict(SETTINGS, workers=1))


def test_worker_processes_make_the_same_mesh(extension, made_here):
    reconstruct = extension.module("engine.reconstruct").reconstruct
    runners = extension.module("engine.tile_runners")
    assert runners.__package__.startswith("bl_ext.")  # the engine as the extension's subpackage
    cloud, one = made_here
    two = reconstruct(cloud, dict(SETTINGS, workers=2))
    assert one.stats["tiles"] >= 4
    assert one.stats["worker_processes"] == 0 and two.stats["worker_processes"] == 2
    assert np.array_equal(one.mesh.vertices, two.mesh.vertices)
    assert np.array_equal(one.mesh.faces, two.mesh.faces)
    assert len(one.mesh.faces) > 1000


def test_workers_that_cannot_start_leave_the_tiles_to_blender(extension, made_here,
                                                               monkeypatch):
    reconstruct = extension.module("engine.reconstruct").reconstruct
    runners = extension.module("engine.tile_runners")
    monkeypatch.setattr(runners, "WORKER_SETUP", "raise SystemExit(3)  # {names}{folder}"
                                                 "{engine}{parent}")
    messages = []
    cloud, one = made_here
    two = reconstruct(cloud, dict(SETTINGS, workers=2),
                      progress=lambda fraction, text: messages.append(text))
    assert two.stats["worker_processes"] == 0
    assert any("worker processes could not start" in text for text in messages)
    assert np.array_equal(one.mesh.faces, two.mesh.faces)
