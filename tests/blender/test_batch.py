"""scripts/batch_reconstruct.py as users run it: a separate Blender (or bpy-module) process."""

import subprocess
import sys
from pathlib import Path

import bpy
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "scripts" / "batch_reconstruct.py"


def run_batch(*args):
    if bpy.app.binary_path:  # inside a real Blender: the same binary, in the background
        command = [bpy.app.binary_path, "-b", "--factory-startup", "--python-exit-code", "1",
                   "--python", str(SCRIPT), "--", *args]
    else:  # the bpy module: a plain Python script
        command = [sys.executable, str(SCRIPT), *args]
    return subprocess.run(command, capture_output=True, text=True, timeout=600)


def test_batch_writes_meshes_blend_and_preview_and_reports_bad_inputs(extension, tmp_path):
    io = extension.module("engine.io")
    geometry = extension.module("engine.geometry")
    count = 6000
    i = np.arange(count) + 0.5
    polar, azimuth = np.arccos(1 - 2 * i / count), np.pi * (1 + 5 ** 0.5) * i
    points = 0.5 * np.c_[np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar),
                         np.cos(polar)]
    inputs = tmp_path / "scans"
    inputs.mkdir()
    no_faces = np.zeros((0, 3), dtype=np.int64)
    io.write_mesh(inputs / "ball.ply", geometry.Mesh(points, no_faces))
    io.write_mesh(inputs / "three.ply", geometry.Mesh(np.eye(3), no_faces))
    out = tmp_path / "out"

    done = run_batch(str(inputs), "--output", str(out), "--resolution", "48",
                     "--blend", str(out / "all.blend"), "--preview", str(out / "preview.png"))
    print(done.stdout[-3000:], done.stderr[-3000:])
    assert done.returncode == 1, "one input failed, so the run must fail"
    assert "three.ply: error: only 3 points" in done.stderr
    assert "done: 1 of 2 reconstructed" in done.stdout

    mesh = io.read_mesh(out / "ball.ply")
    assert len(mesh.faces) > 2000
    error = np.abs(np.linalg.norm(mesh.vertices, axis=1) - 0.5)
    assert error.mean() < 0.003, "the batch mesh lies on the sphere"
    assert not (out / "three.ply").exists()

    with bpy.data.libraries.load(str(out / "all.blend")) as (data_from, data_to):
        assert "ball" in data_from.objects
    image = bpy.data.images.load(str(out / "preview_ball.png"))
    pixels = np.empty(len(image.pixels), dtype=np.float32)
    image.pixels.foreach_get(pixels)
    assert image.size[:] == (960, 720)
    assert pixels.reshape(-1, 4)[:, :3].std() > 0.05, "the preview shows something"
    bpy.data.images.remove(image)


def test_batch_refuses_bad_options_with_usage(tmp_path):
    done = run_batch(str(tmp_path), "--output", str(tmp_path / "o"), "--radius-mode", "magic")
    assert done.returncode == 2
    assert "invalid choice: 'magic'" in done.stderr
