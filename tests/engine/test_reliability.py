"""Never destroy a user's file, refuse bad requests before any work, no tracebacks.

Each test meets one way a run can go wrong as a user meets it (mostly through the CLI or the
batch script in a subprocess) and checks what the user gets. None needs Blender: the batch
script runs engine-only, with ``bpy`` blocked.
"""

import hashlib
import os
import signal
import struct
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from engine.errors import InputError
from engine.geometry import Mesh
from engine.io import read_mesh, read_point_cloud, write_mesh

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "scripts" / "batch_reconstruct.py"
NO_FACES = np.zeros((0, 3), np.int64)


def engine_cli(*args, timeout=120):
    """``python -m engine ARGS`` from the repository root -> CompletedProcess (text)."""
    return subprocess.run([sys.executable, "-m", "engine", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)


_NO_BPY = ("import runpy, sys; sys.modules['bpy'] = None; script = sys.argv[1]; "
           "sys.argv = [script] + sys.argv[2:]; runpy.run_path(script, run_name='__main__')")


def batch(*args, timeout=300):
    """scripts/batch_reconstruct.py ARGS in a plain Python where ``import bpy`` fails."""
    return subprocess.run([sys.executable, "-c", _NO_BPY, str(SCRIPT), *map(str, args)],
                          cwd=ROOT, capture_output=True, text=True, timeout=timeout)


def sphere(count=2000, radius=0.5):
    """``count`` evenly spread points on a sphere (a Fibonacci lattice)."""
    i = np.arange(count) + 0.5
    polar, azimuth = np.arccos(1 - 2 * i / count), np.pi * (1 + 5 ** 0.5) * i
    return radius * np.c_[np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar),
                          np.cos(polar)]


def digest(path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def leftovers(folder):
    """Temporary files a write left in ``folder``."""
    return sorted(p.name for p in Path(folder).iterdir() if p.name.endswith(".tmp"))


@pytest.fixture
def scan(tmp_path):
    """A small point-cloud file (2000 points on a sphere, binary PLY)."""
    path = tmp_path / "scan.ply"
    write_mesh(path, Mesh(sphere(), NO_FACES))
    return path


# ---------------------------------------------------------------- 1. output == input


@pytest.mark.parametrize("spelling", ["same", "relative", "symlink", "hardlink"])
def test_reconstruct_refuses_an_output_that_is_its_input(scan, spelling):
    before = digest(scan)
    output = {"same": scan, "relative": Path(os.path.relpath(scan, ROOT)),
              "symlink": scan.parent / "link.ply", "hardlink": scan.parent / "hard.ply"}[spelling]
    if spelling == "symlink":
        output.symlink_to(scan)
    elif spelling == "hardlink":
        os.link(scan, output)
    started = time.perf_counter()
    done = engine_cli("reconstruct", scan, output, "--resolution", "32")
    assert done.returncode == 2, done.stderr
    assert time.perf_counter() - started < 5, "refused before any work"
    assert f"output {output} is the input {scan}" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr and "%" not in done.stderr, "no stage ever started"
    assert digest(scan) == before


def test_mesh_udf_refuses_an_output_that_is_its_grid(tmp_path):
    grid = tmp_path / "grid.npz"
    np.savez(grid, udf=np.ones((8, 8, 8), np.float32), origin=np.zeros(3), spacing=0.1)
    before = digest(grid)
    done = engine_cli("mesh-udf", grid, grid)
    assert done.returncode == 2
    assert f"output {grid} is the input {grid}" in done.stderr, done.stderr
    assert digest(grid) == before


def test_batch_refuses_to_write_meshes_over_its_inputs(tmp_path):
    folder = tmp_path / "scans"
    folder.mkdir()
    write_mesh(folder / "a.ply", Mesh(sphere(), NO_FACES))
    write_mesh(folder / "b.obj", Mesh(sphere(1500), NO_FACES))
    before = {p.name: digest(p) for p in folder.iterdir()}
    started = time.perf_counter()
    done = batch(folder, "--output", folder, "--resolution", "32")  # a.ply -> a.ply
    assert done.returncode == 2, done.stdout + done.stderr
    assert time.perf_counter() - started < 10
    assert f"would be written to {folder / 'a.ply'}, which is the input" in done.stderr
    assert "points" not in done.stdout, "no input was even read"
    assert {p.name: digest(p) for p in folder.iterdir()} == before
    # b.obj -> b.ply would be fine, but a.ply's mesh is checked first: nothing was written
    assert sorted(p.name for p in folder.iterdir()) == ["a.ply", "b.obj"]


# ---------------------------------------------------------------- 2. atomic writes


def test_a_write_that_fails_midway_leaves_the_previous_file(tmp_path, monkeypatch):
    import engine.io as engine_io

    target = tmp_path / "mesh.ply"
    write_mesh(target, Mesh(sphere(100), NO_FACES))
    before = digest(target)

    def broken(file, *arrays):
        file.write(b"ply\nformat binary_little_endian 1.0\n" + bytes(5000))
        raise KeyboardInterrupt  # Ctrl-C in the middle of the write

    monkeypatch.setitem(engine_io._WRITERS, "ply", broken)
    with pytest.raises(KeyboardInterrupt):
        write_mesh(target, Mesh(sphere(3000), NO_FACES))
    assert digest(target) == before
    assert leftovers(tmp_path) == []


_BIG_WRITE = textwrap.dedent("""
    import signal, sys
    import numpy as np
    sys.path.insert(0, {root!r})
    from engine.errors import InputError
    from engine.geometry import Mesh
    from engine.io import write_mesh
    limit = {limit}
    if limit:
        import resource
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # EFBIG instead of death
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    rng = np.random.default_rng(0)
    vertices = rng.normal(size=(400_000, 3))
    faces = rng.integers(0, len(vertices), size=(800_000, 3))
    print("writing", flush=True)
    try:
        write_mesh({target!r}, Mesh(vertices, faces))
    except InputError as error:
        print("refused:", error, flush=True)
        sys.exit(2)
    print("written", flush=True)
""")


def test_a_killed_write_leaves_the_previous_file_intact(tmp_path):
    target = tmp_path / "mesh.obj"
    write_mesh(target, Mesh(sphere(500), np.array([[0, 1, 2], [2, 3, 4]])))
    before, stat = digest(target), target.stat()
    code = _BIG_WRITE.format(root=str(ROOT), limit=0, target=str(target))
    child = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "writing"
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:  # until the write has put bytes somewhere
            temporary = [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]
            now = target.stat()
            if (any(p.stat().st_size for p in temporary)
                    or (now.st_size, now.st_mtime_ns) != (stat.st_size, stat.st_mtime_ns)):
                break
            time.sleep(0.002)
        else:
            pytest.fail("the child never started writing")
        child.send_signal(signal.SIGKILL)
        child.wait(timeout=10)
    finally:
        if child.poll() is None:
            child.kill()
        child.stdout.close()
    assert child.returncode == -signal.SIGKILL, "killed midway, not finished"
    assert digest(target) == before, "the previous mesh is intact"
    assert len(read_mesh(target).vertices) == 500


@pytest.mark.skipif(not hasattr(signal, "SIGXFSZ"), reason="needs POSIX file-size limits")
def test_a_file_size_limit_leaves_the_previous_file_intact(tmp_path):
    target = tmp_path / "mesh.ply"
    write_mesh(target, Mesh(sphere(500), np.array([[0, 1, 2], [2, 3, 4]])))
    before = digest(target)
    code = _BIG_WRITE.format(root=str(ROOT), limit=2_000_000, target=str(target))
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 2, done.stdout + done.stderr
    assert "refused: mesh.ply: cannot be written (File too large)" in done.stdout
    assert digest(target) == before
    assert leftovers(tmp_path) == [], "the partial temporary file is removed"


def test_a_replaced_file_keeps_its_permissions(tmp_path):
    target = tmp_path / "mesh.off"
    write_mesh(target, Mesh(sphere(50), NO_FACES))
    os.chmod(target, 0o640)
    write_mesh(target, Mesh(sphere(60), NO_FACES))
    assert target.stat().st_mode & 0o777 == 0o640
    assert len(read_mesh(target).vertices) == 60 and leftovers(tmp_path) == []


# ---------------------------------------------------------------- 3. outputs checked first


def _read_only_folder(tmp_path):
    """A folder no file can be created in (``/sys`` when root ignores the permissions)."""
    folder = tmp_path / "locked"
    folder.mkdir()
    folder.chmod(0o555)
    if not os.access(folder, os.W_OK):
        return folder
    try:  # root: a sysfs folder refuses new files even to root
        os.close(os.open("/sys/udfr_probe.ply", os.O_WRONLY | os.O_CREAT | os.O_EXCL))
    except OSError:
        return Path("/sys")
    os.remove("/sys/udfr_probe.ply")
    pytest.skip("no folder here is read-only to this user")


@pytest.mark.parametrize("case", ["missing folder", "unknown extension", "no extension",
                                  "a folder", "read-only folder"])
def test_bad_outputs_are_refused_before_the_input_is_read(tmp_path, case):
    broken = tmp_path / "broken.ply"
    broken.write_bytes(b"ply\nthis input is never read\n")
    output = {"missing folder": tmp_path / "nowhere" / "mesh.ply",
              "unknown extension": tmp_path / "mesh.abc", "no extension": tmp_path / "mesh",
              "a folder": tmp_path}.get(case)
    if case == "read-only folder":
        output = _read_only_folder(tmp_path) / "mesh.ply"
    started = time.perf_counter()
    done = engine_cli("reconstruct", broken, output, "--resolution", "32")
    elapsed = time.perf_counter() - started
    assert done.returncode == 2, done.stderr
    assert done.stderr.startswith(f"error: output {output}"), done.stderr
    problem = {"missing folder": "does not exist", "unknown extension": "cannot write '.abc'",
               "no extension": "cannot write no extension", "a folder": "is a folder",
               "read-only folder": "cannot create files in"}[case]
    assert problem in done.stderr, done.stderr
    assert elapsed < 2.0, f"refused in {elapsed:.2f} s"
    assert not os.path.exists(tmp_path / "nowhere")


def _gpu_usable() -> bool:
    import importlib.util

    from engine.commands import preflight

    spec = importlib.util.find_spec("torch")
    return (spec is not None and preflight._torch_cuda_build(spec) is not None
            and preflight._cuda_driver_present())


@pytest.mark.skipif(_gpu_usable(), reason="this machine has a CUDA GPU")
def test_cuda_without_a_gpu_is_refused_at_once_on_a_large_cloud(tmp_path):
    cloud = tmp_path / "big.npy"
    np.save(cloud, np.random.default_rng(0).normal(size=(2_000_000, 3)))
    started = time.perf_counter()
    done = engine_cli("reconstruct", cloud, tmp_path / "mesh.ply", "--device", "cuda")
    elapsed = time.perf_counter() - started
    assert done.returncode == 2 and "device 'cuda'" in done.stderr, done.stderr
    assert "%" not in done.stderr, "no stage started"
    assert elapsed < 2.0, f"refused in {elapsed:.2f} s"
    started = time.perf_counter()
    done = engine_cli("reconstruct", cloud, tmp_path / "no" / "mesh.ply")
    assert done.returncode == 2 and "does not exist" in done.stderr
    assert time.perf_counter() - started < 2.0


def test_check_output_path_accepts_a_good_output_and_leaves_no_probe(tmp_path):
    from engine.io import check_output_path

    assert check_output_path(tmp_path / "mesh.stl", [tmp_path / "scan.ply"]) == str(
        tmp_path / "mesh.stl")
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "old.ply").write_bytes(b"x")
    (tmp_path / "old.ply").chmod(0o444)
    if not os.access(tmp_path / "old.ply", os.W_OK):
        with pytest.raises(InputError, match="exists and is read-only"):
            check_output_path(tmp_path / "old.ply")


def test_stl_is_written_as_binary_triangles_and_reads_back(tmp_path):
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float64) + 10
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    write_mesh(tmp_path / "tet.stl", Mesh(vertices, faces))
    data = (tmp_path / "tet.stl").read_bytes()
    assert len(data) == 84 + 50 * 4 and struct.unpack_from("<I", data, 80)[0] == 4
    normal = np.frombuffer(data, "<f4", 3, 84)
    np.testing.assert_allclose(normal, [0, 0, -1], atol=1e-6)  # outward, from the winding
    back = read_mesh(tmp_path / "tet.stl")
    assert len(back.vertices) == 4 and len(back.faces) == 4
    np.testing.assert_allclose(back.vertices[back.faces], vertices[faces], atol=1e-5)
    ascii_stl = ("solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n"
                 "vertex 0 1 0\nendloop\nendfacet\nendsolid t\n")
    (tmp_path / "a.stl").write_text(ascii_stl)
    assert read_mesh(tmp_path / "a.stl").faces.tolist() == [[0, 2, 1]]
    with pytest.raises(InputError, match="STL stores triangles only"):
        write_mesh(tmp_path / "points.stl", Mesh(vertices, NO_FACES))
    (tmp_path / "cut.stl").write_bytes(data[:-10])
    with pytest.raises(InputError, match="cut.stl: a binary STL of 4 triangles needs 284"):
        read_mesh(tmp_path / "cut.stl")


# ---------------------------------------------------------------- 4. empty results


def _ten_points(path):
    np.savetxt(path, np.random.default_rng(1).normal(size=(10, 3)))


def test_an_empty_result_is_an_error_and_writes_nothing(tmp_path):
    _ten_points(tmp_path / "ten.xyz")
    previous = tmp_path / "mesh.ply"
    write_mesh(previous, Mesh(sphere(100), np.array([[0, 1, 2]])))
    before = digest(previous)
    done = engine_cli("reconstruct", tmp_path / "ten.xyz", previous, "--resolution", "32",
                      "--outliers", "keep", "--radius-mode", "fixed")  # learned finds a surface
    assert done.returncode == 2, done.stderr
    assert "error: ten.xyz: the reconstruction found no surface" in done.stderr, done.stderr
    assert "nothing was written" in done.stderr and "wrote" not in done.stderr
    assert "try a larger --radius or a lower --resolution" in done.stderr
    assert digest(previous) == before, "the previous mesh is not replaced by an empty one"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mesh.ply", "ten.xyz"]


def test_specks_count_as_an_empty_result_but_a_small_surface_does_not():
    from engine.commands.preflight import MIN_PIECE_FACES, check_result

    def strip(count):  # a strip of 2 * count triangles
        top = np.c_[np.arange(count + 1), np.zeros(count + 1), np.zeros(count + 1)]
        vertices = np.concatenate([top, top + [0, 1, 0]])
        i = np.arange(count)
        n = count + 1
        faces = np.concatenate([np.c_[i, i + 1, i + n], np.c_[i + 1, i + n + 1, i + n]])
        return Mesh(vertices, faces)

    check_result(strip(MIN_PIECE_FACES // 2))  # one piece of MIN_PIECE_FACES faces: a surface
    specks = [strip(2) for _ in range(30)]  # thirty pieces of four faces
    offsets = np.cumsum([0] + [len(m.vertices) for m in specks[:-1]])
    mesh = Mesh(np.concatenate([m.vertices + [5 * k, 0, 0] for k, m in enumerate(specks)]),
                np.concatenate([m.faces + o for m, o in zip(specks, offsets)]))
    with pytest.raises(InputError, match="found no surface, only 30 specks of 4 faces or fewer"):
        check_result(mesh)
    with pytest.raises(InputError, match=r"found no surface \(3 vertices, 0 faces\)"):
        check_result(Mesh(np.eye(3), NO_FACES))
    with pytest.raises(InputError, match=r"try a larger --parent-radius \(with --custom-range\)"):
        check_result(Mesh(np.eye(3), NO_FACES), radius_mode="learned")


def test_the_batch_agrees_an_empty_result_is_a_failure(tmp_path):
    folder = tmp_path / "scans"
    folder.mkdir()
    _ten_points(folder / "ten.xyz")
    done = batch(folder, "--output", tmp_path / "out", "--resolution", "32",
                 "--outliers", "keep", "--radius-mode", "fixed")
    assert done.returncode == 1, done.stdout + done.stderr
    assert "ten.xyz: error: the reconstruction found no surface" in done.stderr
    assert "done: 0 of 1 reconstructed" in done.stdout
    assert list((tmp_path / "out").iterdir()) == []


# ---------------------------------------------------------------- 5. bad settings, corrupt files


@pytest.mark.parametrize("changes, problem", [
    ({"seed": -1}, "seed -1 is outside [0, 4294967295]"),
    ({"seed": 2 ** 32}, "seed 4294967296 is outside"),
    ({"seed": 1.5}, "seed must be a whole number, not 1.5 (float)"),
    ({"seed": True}, "seed must be a whole number, not True (bool)"),
    ({"resolution": "64"}, "resolution must be a whole number, not '64' (str)"),
    ({"radius": "0.02"}, "radius must be a number, not '0.02' (str)"),
    ({"radius": float("nan")}, "radius must be a finite number"),
    ({"device": None}, "device must be a string"),
    ({"resolutoin": 64}, "unknown settings: resolutoin"),
])
def test_bad_settings_from_python_are_refused_before_any_work(changes, problem):
    from engine.reconstruct import reconstruct
    from engine.settings import ReconstructSettings

    calls = []
    progress = lambda fraction, message: calls.append(message)  # noqa: E731
    with pytest.raises(InputError) as caught:
        reconstruct(sphere(), changes, progress)  # settings as a dict
    assert problem in str(caught.value)
    if "unknown" not in problem:
        with pytest.raises(InputError, match=problem.replace("(", r"\(").replace(")", r"\)")
                           .replace("[", r"\[").replace("]", r"\]")):
            reconstruct(sphere(), ReconstructSettings(**changes), progress)
    assert calls == [], "no stage started"


def test_settings_may_be_a_dict_but_not_anything_else():
    from engine.reconstruct import reconstruct
    from engine.settings import ReconstructSettings

    assert ReconstructSettings.coerce({"resolution": 64, "seed": 3}) == ReconstructSettings(
        resolution=64, seed=3)
    assert ReconstructSettings.coerce(None) == ReconstructSettings()
    with pytest.raises(InputError, match="settings must be a ReconstructSettings or a dict"):
        reconstruct(sphere(), "fast")


def test_cli_negative_seed_is_refused_at_once(scan, tmp_path):
    started = time.perf_counter()
    done = engine_cli("reconstruct", scan, tmp_path / "mesh.ply", "--seed", "-1")
    assert done.returncode == 2 and "error: seed -1 is outside" in done.stderr, done.stderr
    assert time.perf_counter() - started < 2.0 and "%" not in done.stderr


def _npy(header: str, body: bytes = bytes(72), magic=b"\x93NUMPY\x01\x00") -> bytes:
    """An NPY file with a hand-written header dict (padded the way numpy pads it)."""
    text = header.encode("latin1")
    padding = (64 - (len(magic) + 2 + len(text) + 1) % 64) % 64
    text += b" " * padding + b"\n"
    return magic + struct.pack("<H", len(text)) + text + body


CORRUPT_NPY = {
    "unclosed": (_npy("{'descr': '<f8', 'fortran_order': False, 'shape': (3, 3"),
                 "corrupt NPY header"),  # numpy: tokenize.TokenError
    "string": (_npy("{'descr': '<f8', 'fortran_order': False, 'shape': (3, 3), '''"),
               "corrupt NPY header"),
    "dtype": (_npy("{'descr': 'x9', 'fortran_order': False, 'shape': (3, 3), }"),
              "corrupt NPY header"),
    "huge": (_npy("{'descr': '<f8', 'fortran_order': False, 'shape': (100000000000, 3), }"),
             "claims a (100000000000, 3) array of float64 (2.18 TiB)"),  # numpy: MemoryError
    "negative": (_npy("{'descr': '<f8', 'fortran_order': False, 'shape': (-3, 3), }"),
                 "impossible shape (-3, 3)"),
    "version": (_npy("{'descr': '<f8', 'fortran_order': False, 'shape': (3, 3), }",
                     magic=b"\x93NUMPY\x09\x00"), "corrupt NPY header"),
    "header cut": (_npy("{'descr': '<f8', 'fortran_order': False, 'shape': (3, 3), }")[:40],
                   "corrupt NPY header"),
    "objects": (_npy("{'descr': '|O', 'fortran_order': False, 'shape': (3, 3), }"),
                "holds object values"),
    "body cut": (_npy("{'descr': '<f8', 'fortran_order': False, 'shape': (30, 3), }"),
                 "only 72 bytes follow its header"),
}


@pytest.mark.parametrize("case", sorted(CORRUPT_NPY))
def test_corrupt_npy_headers_give_one_message_naming_the_file(tmp_path, case):
    content, problem = CORRUPT_NPY[case]
    (tmp_path / "bad.npy").write_bytes(content)
    with pytest.raises(InputError) as caught:
        read_point_cloud(tmp_path / "bad.npy")
    message = str(caught.value)
    assert message.startswith("bad.npy: ") and problem in message and "\n" not in message


def test_corrupt_npz_members_give_one_message_naming_the_file(tmp_path):
    import zipfile

    huge = CORRUPT_NPY["huge"][0]
    with zipfile.ZipFile(tmp_path / "huge.npz", "w") as archive:
        archive.writestr("points.npy", huge)
    with pytest.raises(InputError, match=r"^huge\.npz: 'points' claims a \(100000000000, 3\)"):
        read_point_cloud(tmp_path / "huge.npz")
    with zipfile.ZipFile(tmp_path / "syntax.npz", "w") as archive:
        archive.writestr("points.npy", CORRUPT_NPY["unclosed"][0])
    with pytest.raises(InputError, match=r"^syntax\.npz: 'points' has a corrupt NPY header"):
        read_point_cloud(tmp_path / "syntax.npz")
    np.savez_compressed(tmp_path / "good.npz", points=sphere(500))
    data = (tmp_path / "good.npz").read_bytes()
    (tmp_path / "cut.npz").write_bytes(data[:len(data) // 2])
    with pytest.raises(InputError, match=r"^cut\.npz: not a readable NPZ archive"):
        read_point_cloud(tmp_path / "cut.npz")
    # an extra member we do not use is never read, however big it claims to be
    with zipfile.ZipFile(tmp_path / "extra.npz", "w") as archive:
        archive.writestr("points.npy", _npy_bytes(sphere(300)))
        archive.writestr("junk.npy", huge)
    assert len(read_point_cloud(tmp_path / "extra.npz")) == 300


def test_mesh_udf_corrupt_grid_gives_one_message(tmp_path):
    import zipfile

    with zipfile.ZipFile(tmp_path / "grid.npz", "w") as archive:
        archive.writestr("udf.npy", _npy("{'descr': '<f4', 'fortran_order': False, "
                                         "'shape': (100000, 100000, 100000), }"))
        archive.writestr("origin.npy", _npy_bytes(np.zeros(3)))
        archive.writestr("spacing.npy", _npy_bytes(np.float64(0.1)))
    done = engine_cli("mesh-udf", tmp_path / "grid.npz", tmp_path / "mesh.ply")
    assert done.returncode == 2, done.stderr
    assert done.stderr.startswith("error: grid.npz: 'udf' claims a (100000, 100000, 100000)")
    assert "Traceback" not in done.stderr
    np.savez(tmp_path / "flat.npz", udf=np.ones((4, 4, 4), np.float32), origin=np.zeros(3),
             spacing=0.0)
    done = engine_cli("mesh-udf", tmp_path / "flat.npz", tmp_path / "mesh.ply")
    assert done.returncode == 2 and "spacing must be a positive number" in done.stderr


def _npy_bytes(array) -> bytes:
    import io

    buffer = io.BytesIO()
    np.save(buffer, array)
    return buffer.getvalue()


def _laz(path, count=20000):
    laspy = pytest.importorskip("laspy")
    pytest.importorskip("lazrs")
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales, header.offsets = [1e-4] * 3, [0, 0, 0]
    las = laspy.LasData(header)
    las.x, las.y, las.z = sphere(count).T
    las.write(str(path))
    return path.read_bytes()


@pytest.mark.parametrize("damage", ["cut at 10000", "32 bytes inserted at 3808",
                                    "cut before the chunk table", "chunk table cut"])
def test_corrupt_laz_gives_one_message_and_the_process_survives(tmp_path, damage):
    good = _laz(tmp_path / "good.laz")
    bad = {"cut at 10000": good[:10000],
           "32 bytes inserted at 3808": good[:3808] + bytes(range(32)) + good[3808:],
           "cut before the chunk table": good[:len(good) - 20],
           "chunk table cut": good[:-3]}[damage]
    (tmp_path / "bad.laz").write_bytes(bad)
    # inserted bytes once made lazrs abort the whole process: run it in a child
    done = engine_cli("reconstruct", tmp_path / "bad.laz", tmp_path / "mesh.ply",
                      "--resolution", "32", timeout=60)
    assert done.returncode == 2, (done.returncode, done.stderr[-2000:])
    assert done.stderr.startswith("error: bad.laz: "), done.stderr
    assert "Traceback" not in done.stderr and "LazrsError:" not in done.stderr.split("(")[0]
    assert len(done.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "mesh.ply").exists()


def test_las_header_claiming_more_points_than_the_file_holds(tmp_path):
    laspy = pytest.importorskip("laspy")
    header = laspy.LasHeader(point_format=3, version="1.2")
    las = laspy.LasData(header)
    las.x, las.y, las.z = sphere(1000).T
    las.write(str(tmp_path / "good.las"))
    data = (tmp_path / "good.las").read_bytes()
    (tmp_path / "cut.las").write_bytes(data[:-100])
    with pytest.raises(InputError, match=r"^cut\.las: the file claims 1,000 points of 34 bytes"):
        read_point_cloud(tmp_path / "cut.las")
    count = bytearray(data)
    struct.pack_into("<I", count, 107, 4_000_000_000)
    (tmp_path / "count.las").write_bytes(bytes(count))
    with pytest.raises(InputError, match=r"claims 4,000,000,000 points"):
        read_point_cloud(tmp_path / "count.las")
    offset = bytearray(data)
    struct.pack_into("<I", offset, 96, len(data) + 10)
    (tmp_path / "offset.las").write_bytes(bytes(offset))
    with pytest.raises(InputError, match=r"point data offset \d+ do not fit"):
        read_point_cloud(tmp_path / "offset.las")
    assert len(read_point_cloud(tmp_path / "good.las")) == 1000


# ---------------------------------------------------------------- 6. the batch goes on


def test_batch_reports_each_bad_input_goes_on_and_ends_with_a_summary(tmp_path):
    folder = tmp_path / "scans"
    folder.mkdir()
    write_mesh(folder / "ball.ply", Mesh(sphere(), NO_FACES))
    (folder / "cut.laz").write_bytes(_laz(tmp_path / "whole.laz")[:10000])
    (folder / "bad.npy").write_bytes(CORRUPT_NPY["huge"][0])
    (folder / "notes.txt").write_text("These are the scans from the site visit.\n"
                                      "Keep them safe; the originals are gone.\n")
    out = tmp_path / "out"
    done = batch(folder, "--output", out, "--resolution", "32")
    print(done.stdout[-3000:], done.stderr[-3000:])
    assert done.returncode == 1, "some inputs failed"
    assert "Traceback" not in done.stderr
    for name in ("bad.npy", "cut.laz", "notes.txt"):
        assert f"{name}: error: {name}: " in done.stderr
        assert f"failed: {folder / name}: {name}: " in done.stdout
    assert "done: 1 of 4 reconstructed" in done.stdout
    assert done.stdout.rindex("done: 1 of 4") > done.stdout.index("ball.ply: wrote"), \
        "the good file after the bad ones was still reconstructed"
    assert sorted(p.name for p in out.iterdir()) == ["ball.ply"]
    mesh = read_mesh(out / "ball.ply")
    assert len(mesh.faces) > 1000
    assert np.abs(np.linalg.norm(mesh.vertices, axis=1) - 0.5).mean() < 0.01


# ---------------------------------------------------------------- 10. the small ones


@pytest.mark.parametrize("name, content, problem", [
    ("negative.off", "OFF\n-1 0 0\n0 0 0\n1 0 0\n0 1 0\n", "counts cannot be negative"),
    ("few.off", "OFF\n2 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
     "the header gives 2 vertices and 1 faces, but the file has 1 more line: the counts"),
    ("fewer.off", "OFF\n2 2 0\n0 0 0\n1 0 0\n0.5 1 0\n3 0 1 2\n",
     "face line 1 ('0.5 1 0') is not 'n i1 .. in' with whole numbers; if it is a vertex, "
     "the vertex count in the header is too small"),
    ("half.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2.5\n", "face line 1"),
    ("rows.ply", "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
                 "property float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n",
     "the header declares 2 vertices, but 3 more values follow them"),
])
def test_off_and_ascii_ply_counts_that_do_not_match_the_body(tmp_path, name, content, problem):
    (tmp_path / name).write_text(content)
    with pytest.raises(InputError) as caught:
        read_mesh(tmp_path / name)
    assert str(caught.value).startswith(f"{name}: ") and problem in str(caught.value)


def test_a_nan_message_names_the_file(tmp_path):
    rows = "".join(f"{i} {i * i % 7} {i % 3}\n" for i in range(20))
    (tmp_path / "holes.xyz").write_text(rows + "nan 0 0\n1 inf 2\n")
    done = engine_cli("reconstruct", tmp_path / "holes.xyz", tmp_path / "mesh.ply")
    assert done.returncode == 2
    assert "error: holes.xyz: 2 of 22 points have NaN or infinite coordinates" in done.stderr


_SLOW_WRITE_CLI = textwrap.dedent("""
    import signal, sys, time
    # Ctrl-C as in a terminal, even when the suite itself was started in the background
    # (where a shell without job control starts it, and so this child, ignoring SIGINT)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    sys.path.insert(0, {root!r})
    import engine.io
    from engine.__main__ import main
    real = engine.io._WRITERS["ply"]

    def slow(file, *arrays):  # a write that takes long enough to be interrupted
        file.write(b"ply\\n")
        file.flush()
        print("writing", flush=True)
        for _ in range(600):
            file.write(bytes(1000))
            time.sleep(0.01)
        real(file, *arrays)

    engine.io._WRITERS["ply"] = slow
    sys.exit(main(["reconstruct", {cloud!r}, {output!r}, "--resolution", "32",
                   "--udf-source", "nearest", "--quiet"]))
""")


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_during_the_cli_write_cancels_and_keeps_the_previous_file(tmp_path, scan,
                                                                           signum):
    output = tmp_path / "mesh.ply"
    write_mesh(output, Mesh(sphere(100), np.array([[0, 1, 2]])))
    before = digest(output)
    code = _SLOW_WRITE_CLI.format(root=str(ROOT), cloud=str(scan), output=str(output))
    child = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "writing"
        time.sleep(0.1)
        child.send_signal(signum)
        _, err = child.communicate(timeout=20)
    finally:
        if child.poll() is None:
            child.kill()
    assert child.returncode == 130 and "cancelled" in err, (child.returncode, err)
    assert "Traceback" not in err
    assert digest(output) == before
    assert leftovers(tmp_path) == [], "the partial temporary file is removed"
