"""The field on several CPU threads: the same values bit for bit as on one, run after run, in
every radius mode (each batch of queries is cut and computed the same way on any number of
threads, with the BLAS on one thread)."""

import time

import numpy as np
import pytest

from engine import field, radius
from engine.field import compute_udf_band
from engine.settings import ReconstructSettings


def sphere_points(count=6000, radius=0.4, seed=0):
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(count, 3))
    points = radius * points / np.linalg.norm(points, axis=1, keepdims=True)
    return points + rng.normal(scale=0.002, size=points.shape)


@pytest.mark.parametrize("mode", ["fixed", "curvature", "learned"])
def test_one_thread_and_three_give_the_same_field(monkeypatch, mode):
    points = sphere_points()
    settings = ReconstructSettings(resolution=48, radius_mode=mode, device="cpu")
    monkeypatch.setattr(field, "CPU_BATCH", 1500)  # several batches in flight
    fields = []
    for threads in (1, 3, 3):
        monkeypatch.setattr(field, "cpu_threads", lambda: threads)
        monkeypatch.setattr(radius, "cpu_threads", lambda: threads)
        band = compute_udf_band(points, settings)
        assert band.stats["network_queries"] > 4 * 1500
        fields.append(band.grid._band[1])
    np.testing.assert_array_equal(fields[1], fields[0])
    np.testing.assert_array_equal(fields[2], fields[0])


def test_the_radius_share_is_a_part_of_the_field_time():
    band = compute_udf_band(sphere_points(), ReconstructSettings(resolution=48,
                                                                 radius_mode="learned",
                                                                 device="cpu"))
    assert 0 < band.stats["seconds_radius"] < band.stats["seconds_udf"]
    assert "radius_share" not in band.stats


def test_a_cancel_stops_the_threaded_field_without_running_the_other_batches(monkeypatch):
    from engine.errors import Cancelled

    monkeypatch.setattr(field, "CPU_BATCH", 500)
    monkeypatch.setattr(field, "cpu_threads", lambda: 2)
    calls = []

    def predictor(rel, mask):
        calls.append(len(rel))
        return np.zeros(len(rel), dtype=np.float32)

    settings = ReconstructSettings(resolution=48, device="cpu")
    whole = compute_udf_band(sphere_points(), settings, predictor=predictor)
    batches = -(-whole.stats["network_queries"] // 500)
    assert batches >= 12
    calls.clear()
    with pytest.raises(Cancelled):
        compute_udf_band(sphere_points(), settings, predictor=predictor,
                         cancel=lambda: len(calls) >= 2)
    assert len(calls) <= batches // 2  # the batches already running finish; few others start

    def progress(fraction, message):  # a host that stops the run from its progress report
        if message.startswith("network UDF"):
            raise Cancelled()

    calls.clear()
    with pytest.raises(Cancelled):
        compute_udf_band(sphere_points(), settings, predictor=predictor, progress=progress)
    time.sleep(0.5)  # no batch left running behind the raised error either
    assert len(calls) <= batches // 2
