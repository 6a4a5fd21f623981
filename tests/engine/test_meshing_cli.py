"""``python -m engine mesh-udf``: a grid file in, a mesh file out; malformed grids refused."""

import numpy as np
import pytest

from engine.__main__ import main
from engine.errors import InputError
from engine.commands.mesh_udf import load_grid, parse_iso
from lab import analytic as A


def write_grid(path, **overrides):
    grid = A.sample_grid(A.sphere((0.1, 0, 0), 0.3), [-0.4, -0.5, -0.5], [0.6, 0.5, 0.5], 40,
                         exact=False)
    data = {"udf": grid.slab(0, grid.shape[0]), "origin": grid.origin,
            "spacing": np.float64(grid.spacing)}
    data.update(overrides)
    np.savez(path, **{k: v for k, v in data.items() if v is not None})
    return grid


def test_cli_writes_mesh(tmp_path, capsys):
    grid_path = tmp_path / "grid.npz"
    grid = write_grid(grid_path)
    out = tmp_path / "out.ply"
    assert main(["mesh-udf", str(grid_path), str(out), "--iterations", "120", "--iso", "1.0h",
                 "--device", "cpu"]) == 0
    from engine.io import read_mesh
    mesh = read_mesh(str(out))
    d = np.abs(np.linalg.norm(mesh.vertices - [0.1, 0, 0], axis=1) - 0.3) / grid.spacing
    assert len(mesh.faces) > 1000 and d.mean() < 0.05
    err = capsys.readouterr().err
    assert "optimised on cpu" in err


def test_cli_refuses_cuda_without_a_gpu(tmp_path, capsys):
    torch = pytest.importorskip("torch")
    if torch.cuda.is_available():
        pytest.skip("this machine has a GPU")
    grid_path = tmp_path / "grid.npz"
    write_grid(grid_path)
    out = tmp_path / "out.ply"
    assert main(["mesh-udf", str(grid_path), str(out), "--device", "cuda"]) == 2
    assert "cuda" in capsys.readouterr().err and not out.exists()


@pytest.mark.parametrize("overrides,needle", [
    ({"origin": None}, "origin"),
    ({"udf": np.ones((4, 4), np.float32)}, "3-D"),
    ({"udf": np.full((4, 4, 4), np.nan, np.float32)}, "NaN"),
    ({"spacing": np.array([0.1, 0.2])}, "spacing"),
    ({"origin": np.zeros(2)}, "origin"),
])
def test_bad_npz_refused(tmp_path, overrides, needle):
    path = tmp_path / "bad.npz"
    write_grid(path, **overrides)
    with pytest.raises(InputError, match=needle):
        load_grid(str(path))
    assert main(["mesh-udf", str(path), str(tmp_path / "x.ply")]) == 2


def test_iso_parsing():
    assert parse_iso("1.5h", 0.01) == pytest.approx(0.015)
    assert parse_iso("0.02", 0.01) == pytest.approx(0.02)
    assert parse_iso(None, 0.01) is None
    with pytest.raises(InputError):
        parse_iso("abc", 0.01)
    with pytest.raises(InputError):
        parse_iso("-1h", 0.01)
