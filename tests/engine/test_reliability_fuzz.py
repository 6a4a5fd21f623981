"""A seeded fuzz of the readers over a few hundred mutated files.

Small valid PLY (binary and ASCII), OBJ, OFF, STL, GLB, glTF, XYZ, NPY, NPZ, LAS and LAZ files
are truncated, have random bytes inserted or overwritten, or get absurd counts in their
headers. Every mutated file must give a point cloud or one InputError message naming the file:
never another exception, an abort (lazrs once aborted the process on a 32-byte insertion) or a
hang. The files are read in one child process, so an abort fails the test instead of killing
pytest.
"""

import json
import re
import struct
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from engine.geometry import Mesh
from engine.io import write_mesh

ROOT = Path(__file__).resolve().parents[2]
MUTANTS_PER_FILE = 36


def _seeds(folder: Path) -> list:
    """One small valid file per format -> their paths."""
    rng = np.random.default_rng(7)
    points = rng.normal(size=(300, 3))
    faces = rng.integers(0, 300, size=(200, 3))
    normals = points / np.linalg.norm(points, axis=1, keepdims=True)
    colors = rng.uniform(size=(300, 3)).astype(np.float32)
    paths = []
    for name, mesh in (("mesh.ply", Mesh(points, faces, normals, colors)),
                       ("mesh.obj", Mesh(points, faces, normals)),
                       ("mesh.off", Mesh(points, faces, None, colors)),
                       ("mesh.stl", Mesh(points, faces)),
                       ("mesh.glb", Mesh(points, faces, normals, colors)),
                       ("mesh.gltf", Mesh(points, faces, normals, colors))):
        write_mesh(folder / name, mesh)
        paths.append(folder / name)
    ascii_ply = ["ply", "format ascii 1.0", "element vertex 300", "property float x",
                 "property float y", "property float z", "element face 200",
                 "property list uchar int vertex_indices", "end_header"]
    ascii_ply += [" ".join(f"{v:.5f}" for v in row) for row in points]
    ascii_ply += ["3 " + " ".join(map(str, row)) for row in faces]
    (folder / "ascii.ply").write_text("\n".join(ascii_ply) + "\n")
    np.savetxt(folder / "cloud.xyz", np.c_[points, normals], fmt="%.6f")
    np.save(folder / "cloud.npy", points)
    np.savez(folder / "cloud.npz", points=points, normals=normals)
    paths += [folder / "ascii.ply", folder / "cloud.xyz", folder / "cloud.npy",
              folder / "cloud.npz"]
    try:
        import laspy
        header = laspy.LasHeader(point_format=3, version="1.2")
        header.scales, header.offsets = [1e-4] * 3, [0, 0, 0]
        las = laspy.LasData(header)
        las.x, las.y, las.z = points.T
        las.write(str(folder / "cloud.las"))
        paths.append(folder / "cloud.las")
        import lazrs  # noqa: F401
        las.write(str(folder / "cloud.laz"))
        paths.append(folder / "cloud.laz")
    except ImportError:
        pass
    return paths


def _absurd_counts(data: bytes, rng) -> bytes:
    """Replace one header count (text) or 32/64-bit header field (binary) by a huge value."""
    text_counts = list(re.finditer(rb"(element \w+ |^OFF\s+|^)(\d+)", data[:400], re.M))
    if data.startswith((b"ply", b"OFF")) and text_counts:
        match = text_counts[rng.integers(len(text_counts))]
        value = str(rng.choice([0, 2 ** 31, 2 ** 63, 10 ** 30, 4_000_000_000])).encode()
        return data[:match.start(2)] + value + data[match.end(2):]
    if data.startswith(b"LASF"):
        field = int(rng.choice([96, 100, 107, 94, 105]))  # offsets, VLR count, points, sizes
        size = 2 if field in (94, 105) else 4
        mutated = bytearray(data)
        mutated[field:field + size] = rng.integers(0, 256, size, dtype=np.uint8).tobytes()
        return bytes(mutated)
    if data.startswith(b"\x93NUMPY"):
        return re.sub(rb"\(\d+, ", b"(%d, " % int(rng.choice([10 ** 12, 2 ** 62, 0])), data, 1)
    at = int(rng.integers(0, max(1, min(len(data) - 8, 200))))
    return data[:at] + struct.pack("<Q", int(rng.integers(2 ** 40, 2 ** 63))) + data[at + 8:]


def _mutants(path: Path, rng) -> list:
    data = path.read_bytes()
    out = []
    for k in range(MUTANTS_PER_FILE):
        kind = k % 4
        if kind == 0:  # truncated
            mutated = data[:int(rng.integers(0, len(data)))]
        elif kind == 1:  # bytes inserted
            at = int(rng.integers(0, len(data)))
            mutated = data[:at] + rng.integers(0, 256, int(rng.integers(1, 64)),
                                               dtype=np.uint8).tobytes() + data[at:]
        elif kind == 2:  # bytes overwritten, some of them in the header
            mutated = bytearray(data)
            for _ in range(int(rng.integers(1, 6))):
                at = int(rng.integers(0, min(len(data), 400) if rng.random() < 0.5 else len(data)))
                mutated[at] = int(rng.integers(0, 256))
            mutated = bytes(mutated)
        else:
            mutated = _absurd_counts(data, rng)
        name = f"{path.stem}_{k:02d}{path.suffix}"
        (path.parent / "mutants" / name).write_bytes(mutated)
        out.append(name)
    return out


_CHILD = textwrap.dedent("""
    import json, sys, time
    sys.path.insert(0, {root!r})
    from engine.errors import InputError
    from engine.io import read_point_cloud
    import laspy, trimesh  # imported before the clock starts: a slow read is a hang, not an import
    folder = {folder!r}
    for name in json.loads(sys.argv[1]):
        print("reading", name, flush=True)
        started = time.perf_counter()
        try:
            cloud = read_point_cloud(folder + "/" + name)
            outcome = "points %d" % len(cloud)
        except InputError as error:
            message = str(error)
            outcome = "refused" if message.startswith(name + ": ") and "\\n" not in message \\
                else "BAD MESSAGE " + repr(message)
        except BaseException as error:
            outcome = "BUG %s: %s" % (type(error).__name__, str(error)[:200])
        print("result", name, outcome, round(time.perf_counter() - started, 3), flush=True)
    print("finished", flush=True)
""")


def test_mutated_files_give_a_cloud_or_one_message_never_a_crash(tmp_path):
    (tmp_path / "mutants").mkdir()
    rng = np.random.default_rng(20241201)
    names = [name for seed in _seeds(tmp_path) for name in _mutants(seed, rng)]
    assert len(names) >= 250
    code = _CHILD.format(root=str(ROOT), folder=str(tmp_path / "mutants"))
    try:
        done = subprocess.run([sys.executable, "-c", code, json.dumps(names)],
                              capture_output=True, text=True, timeout=50)
    except subprocess.TimeoutExpired as expired:
        output = expired.stdout or b""
        if isinstance(output, bytes):
            output = output.decode(errors="replace")
        hung = output.strip().splitlines()[-1:]
        pytest.fail(f"the readers hung at {hung}", pytrace=False)
    lines = done.stdout.splitlines()
    if done.returncode != 0 or lines[-1:] != ["finished"]:
        reading = [line for line in lines if line.startswith("reading")][-1:]
        pytest.fail(f"the child died (status {done.returncode}) at {reading}: "
                    f"{done.stderr[-1500:]}")
    results = [line.split(" ", 2)[2] for line in lines if line.startswith("result")]
    assert len(results) == len(names)
    bad = [line for line in lines if " BUG " in line or " BAD MESSAGE " in line]
    assert bad == [], "\n".join(bad)
    slow = [line for line in lines if line.startswith("result") and float(line.split()[-1]) > 2]
    assert slow == [], slow
    refused = sum(r.startswith("refused") for r in results)
    assert refused > len(names) // 3, "most mutants are corrupt enough to be refused"
