"""The scale benchmark end to end on a tiny floor: it runs, scores in metres and reports."""

import json

from lab.__main__ import main


def test_a_tiny_floor_runs_scores_and_reports(tmp_path, capsys, monkeypatch):
    from lab.bench import scale

    monkeypatch.setattr(scale, "SAMPLES", 100_000)  # the truth's and the mesh's: a tiny floor
    out = tmp_path / "results"
    status = main(["scale", "--rooms", "1", "--points", "20000", "--voxel-size", "0.04",
                   "--tile-cells", "48", "--no-poisson", "--work", str(tmp_path / "work"),
                   "--out", str(out)])
    assert status == 0
    (path,) = out.glob("floor_*.json")
    rows = json.loads(path.read_text())["rows"]
    ours = rows["ours (voxel 4 cm)"]
    assert ours["tiles"] >= 2
    # both peaks are measured, each in its own process: a worker holds a tile, not the floor
    assert 0.05 < ours["worker_peak_gib"] and 0.05 < ours["peak_gib"] < 8
    # a 4 cm grid over a 20,000-point room: within a couple of centimetres of the truth
    assert ours["cd_cm"] < 3.0 and ours["f1_2cm"] > 0.6 and ours["nc"] > 0.85
    assert "scan's own floor" in rows
    capsys.readouterr()
    assert main(["scale", "--report", "--out", str(out)]) == 0
    table = capsys.readouterr().out
    assert "| 1 rooms, 20,000 points | ours (voxel 4 cm) |" in table

    # the same floor again reuses the built scan; a method that fails says why
    status = main(["scale", "--rooms", "1", "--points", "20000", "--voxel-size", "0.001",
                   "--tile-cells", "4096", "--no-poisson", "--work", str(tmp_path / "work"),
                   "--out", str(out)])
    err = capsys.readouterr().err
    assert status == 1
    assert "reusing" in err and "set tile cells to at most 2,048" in err and "ours failed" in err

    # the nearest-point field, for the tiles' and the stitcher's memory at scale in less time:
    # a file and a row of its own, beside the network's
    status = main(["scale", "--rooms", "1", "--points", "20000", "--voxel-size", "0.04",
                   "--tile-cells", "48", "--no-poisson", "--udf-source", "nearest",
                   "--work", str(tmp_path / "work"), "--out", str(out)])
    assert status == 0
    assert json.loads(path.read_text())["rows"] == rows
    nearest = json.loads((out / "floor_1r_20000p_4cm_nearest.json").read_text())["rows"]
    row = nearest["ours (voxel 4 cm, nearest-point field)"]
    assert row["tiles"] == ours["tiles"] and row["faces"] > 0 and row["cd_cm"] < 5.0

    # --rescore scores each source's own mesh again and keeps the run's time and memory
    nearest_path = out / "floor_1r_20000p_4cm_nearest.json"
    written = json.loads(nearest_path.read_text())
    written["rows"]["ours (voxel 4 cm, nearest-point field)"]["cd_cm"] = -1.0
    nearest_path.write_text(json.dumps(written))
    assert main(["scale", "--rooms", "1", "--points", "20000", "--voxel-size", "0.04",
                 "--udf-source", "nearest", "--rescore", "--work", str(tmp_path / "work"),
                 "--out", str(out)]) == 0
    again = json.loads(nearest_path.read_text())["rows"]["ours (voxel 4 cm, nearest-point field)"]
    assert again == row  # the same mesh, the same samples: the same scores
    assert main(["scale", "--rooms", "1", "--points", "20000", "--voxel-size", "0.04",
                 "--rescore", "--work", str(tmp_path / "work"), "--out", str(out)]) == 0
    assert json.loads(path.read_text())["rows"]["ours (voxel 4 cm)"] == ours


def test_write_cloud_writes_the_scan_the_benchmark_reconstructs(tmp_path):
    import numpy as np

    from engine.io import read_point_cloud
    from lab.bench.floor import make_floor, scan_floor

    path = tmp_path / "floor.ply"
    assert main(["scale", "--rooms", "1", "--points", "3000", "--seed", "2",
                 "--write-cloud", str(path)]) == 0
    points = read_point_cloud(str(path)).points
    _, parts = make_floor(1, 2)
    expected, _ = scan_floor(parts, 3000, 2)
    assert points.shape == expected.shape
    assert np.abs(points - expected).max() < 1e-6  # metres: the file keeps the scan
