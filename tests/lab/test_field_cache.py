"""Proofs for the benchmark's kept fields (``--fields``): a kept field gives the mesh a computed
one gives, bit for bit; any change to the points, the settings or the field's code gives a new
key; the benchmark's time and memory leave those shapes out."""

import numpy as np

from engine.geometry import PointCloud
from lab.bench import field_cache
from lab.bench.harness import summarize
from lab.bench.methods import make_ours


def _cloud(seed: int = 0) -> PointCloud:
    """A sheet folded over itself, 3000 points."""
    rng = np.random.default_rng(seed)
    u, v = rng.uniform(-1, 1, (2, 3000))
    return PointCloud(np.stack([u, v, 0.3 * np.sin(2 * u)], axis=1))


def test_a_kept_field_gives_the_same_mesh(tmp_path):
    ours = make_ours(resolution=40, device="cpu", fields=str(tmp_path))
    first = ours(_cloud())
    assert not ours.field_from_cache
    assert len(list(tmp_path.glob("*.npz"))) == 1
    second = ours(_cloud())
    assert ours.field_from_cache
    assert len(first.faces) > 500
    np.testing.assert_array_equal(first.faces, second.faces)
    np.testing.assert_array_equal(first.vertices, second.vertices)
    # without the folder, the same mesh again
    plain = make_ours(resolution=40, device="cpu")(_cloud())
    np.testing.assert_array_equal(plain.vertices, second.vertices)


def test_points_settings_and_code_key_the_field(tmp_path, monkeypatch):
    from engine.settings import ReconstructSettings

    points = np.asarray(_cloud().points)
    settings = ReconstructSettings(resolution=40)
    key = field_cache.field_key(points, settings, "network")
    assert key == field_cache.field_key(points.copy(), ReconstructSettings(resolution=40),
                                        "network")
    moved = points.copy()
    moved[0, 0] += 1e-9
    assert field_cache.field_key(moved, settings, "network") != key
    assert field_cache.field_key(points, ReconstructSettings(resolution=41), "network") != key
    assert field_cache.field_key(points, settings, "nearest") != key
    monkeypatch.setattr(field_cache, "field_code_hash", lambda: "another engine")
    assert field_cache.field_key(points, settings, "network") != key


def test_the_field_code_is_the_engine_without_its_mesher(tmp_path, monkeypatch):
    engine = tmp_path / "engine"
    (engine / "meshing").mkdir(parents=True)
    (engine / "weights").mkdir()
    (engine / "field.py").write_text("a = 1\n")
    (engine / "meshing" / "optimize.py").write_text("b = 1\n")
    (engine / "weights" / "backbone.npz").write_bytes(b"\0\1")
    monkeypatch.setattr(field_cache, "ENGINE", engine)

    def digest():
        field_cache.field_code_hash.cache_clear()
        return field_cache.field_code_hash()

    before = digest()
    (engine / "meshing" / "optimize.py").write_text("b = 2\n")
    assert digest() == before
    (engine / "field.py").write_text("a = 2\n")
    changed = digest()
    assert changed != before
    (engine / "weights" / "backbone.npz").write_bytes(b"\0\2")
    assert digest() != changed
    field_cache.field_code_hash.cache_clear()


def test_kept_shapes_are_left_out_of_time_and_memory():
    row = {"failed": False, "empty": False, "cd_l1_x100": 0.2, "cd_l2": 1e-5, "f1_0.005": 0.9,
           "f1_0.01": 0.95, "nc": 0.9, "seconds": 30.0, "peak_rss_mb": 900.0,
           "peak_delta_mb": 800.0}
    kept = dict(row, seconds=10.0, peak_rss_mb=400.0, peak_delta_mb=300.0, field_from_cache=True)
    summary = summarize([row, kept])
    assert summary["n"] == 2 and summary["f1_0.005"] == 0.9
    assert summary["seconds"] == 30.0 and summary["peak_rss_mb"] == 900.0
    assert summarize([kept])["seconds"] is None
