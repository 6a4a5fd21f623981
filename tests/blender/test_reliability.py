"""Failures inside Blender (issue 24's cases): the Reconstruct operator and the batch script run
by Blender report bad input, an empty result, an unexpected error, bad settings and an interrupt,
and leave the scene (and the output folder) as they were."""

import signal
import subprocess
import sys
import time
from pathlib import Path

import bpy
import numpy as np
import pytest

from tests.blender.helpers import add_cloud, scene_state, sphere_points

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "scripts" / "batch_reconstruct.py"


def reconstruct_fails(match: str) -> str:
    """Press Reconstruct, expect it to fail with ``match``; return the message."""
    with pytest.raises(RuntimeError, match=match) as error:
        bpy.ops.udf_reconstruction.reconstruct()
    return str(error.value)


# --- the operator ---------------------------------------------------------------------------------

def test_an_empty_result_is_one_error_and_changes_nothing(scene):
    add_cloud("Ten", np.random.default_rng(1).normal(size=(10, 3)))
    scene.udf_reconstruction.radius_mode = "fixed"  # the learned mode's large balls find one
    scene.udf_reconstruction.resolution = 32
    scene.udf_reconstruction.outliers = "keep"
    before = scene_state()
    message = reconstruct_fails("No surface was found")
    assert message.count("Error:") == 1, message
    assert "Raise Radius or lower Resolution" in message
    assert scene_state() == before


def test_nan_points_are_refused_with_what_to_do_and_change_nothing(scene):
    points = sphere_points(2000, 1.0)
    points[[5, 50]] = [np.nan, 0.0, np.inf]
    add_cloud("Broken", points)
    before = scene_state()
    reconstruct_fails(r"2 of 2,?000 points have NaN or infinite coordinates; remove them")
    assert scene_state() == before


def test_an_unexpected_error_is_reported_for_a_bug_report_and_changes_nothing(
        scene, extension, monkeypatch, capsys):
    engine = extension.module("engine.reconstruct")

    def broken(*args, **kwargs):
        raise ValueError("something inside broke")

    monkeypatch.setattr(engine, "reconstruct", broken)
    add_cloud("Scan", sphere_points(2000, 1.0))
    before = scene_state()
    message = reconstruct_fails(r"Reconstruction failed \(ValueError: something inside broke\)")
    assert "Please report this with the text from the system console" in message
    assert "Traceback" in capsys.readouterr().err, "the console gets the traceback"
    assert scene_state() == before


# --- the batch script inside Blender --------------------------------------------------------------

def batch_command(*args):
    if bpy.app.binary_path:  # inside a real Blender: the same binary, in the background
        return [bpy.app.binary_path, "-b", "--factory-startup", "--python-exit-code", "1",
                "--python", str(SCRIPT), "--", *map(str, args)]
    return [sys.executable, str(SCRIPT), *map(str, args)]  # the bpy module


def run_batch(*args):
    return subprocess.run(batch_command(*args), capture_output=True, text=True, timeout=600)


def test_the_batch_reports_each_bad_file_and_saves_only_the_good_mesh(extension, tmp_path):
    io = extension.module("engine.io")
    geometry = extension.module("engine.geometry")
    scans = tmp_path / "scans"
    scans.mkdir()
    no_faces = np.zeros((0, 3), dtype=np.int64)
    io.write_mesh(scans / "ball.ply", geometry.Mesh(0.5 * sphere_points(6000, 1.0), no_faces))
    io.write_mesh(scans / "cut.ply", geometry.Mesh(sphere_points(3000, 1.0), no_faces))
    data = (scans / "cut.ply").read_bytes()
    (scans / "cut.ply").write_bytes(data[:len(data) // 2])
    (scans / "notes.ply").write_text("These are my notes about the scan, not a PLY file.\n")
    header = "{'descr': '<f8', 'fortran_order': False, 'shape': (100000000000, 3), }"
    header += " " * (117 - len(header)) + "\n"
    (scans / "huge.npy").write_bytes(b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little")
                                     + header.encode() + bytes(72))
    np.savetxt(scans / "ten.xyz", np.random.default_rng(1).normal(size=(10, 3)))
    out = tmp_path / "out"

    done = run_batch(scans, "--output", out, "--resolution", "32", "--outliers", "keep",
                     "--radius-mode", "fixed",  # the learned mode finds a surface in ten points
                     "--blend", out / "all.blend")
    print(done.stdout[-3000:], done.stderr[-3000:])
    assert done.returncode == 1
    assert "done: 1 of 5 reconstructed" in done.stdout
    for name in ("cut.ply", "notes.ply", "huge.npy", "ten.xyz"):
        (line,) = [x for x in done.stderr.splitlines() if x.startswith("[") and
                   f" {name}: error: " in x]
        assert "Traceback" not in line
        assert f"failed: {scans / name}: " in done.stdout
    assert "Traceback" not in done.stderr
    assert "found no surface" in done.stderr
    assert sorted(p.name for p in out.iterdir()) == ["all.blend", "ball.ply"]
    with bpy.data.libraries.load(str(out / "all.blend")) as (data_from, _):
        assert list(data_from.objects) == ["ball"]


@pytest.mark.parametrize("option, problem", [
    (("--seed", "-1"), "seed -1 is outside"),
    (("--resolution", "8"), "resolution 8 is outside"),
    (("--device", "cuda", "--radius", "0.5"), None),
])
def test_bad_settings_stop_the_batch_before_any_work(extension, tmp_path, option, problem):
    scans = tmp_path / "scans"
    scans.mkdir()
    np.savetxt(scans / "ball.xyz", sphere_points(3000, 1.0))
    out = tmp_path / "out"
    started = time.perf_counter()
    done = run_batch(scans, "--output", out, "--blend", out / "all.blend", *option)
    print(done.stdout[-2000:], done.stderr[-2000:])
    assert done.returncode == 2
    assert "Traceback" not in done.stderr
    assert "error: " in done.stderr
    if problem:
        assert problem in done.stderr
    assert "reconstructed" not in done.stdout, "no work was started"
    assert not out.exists() or not list(out.iterdir())
    assert time.perf_counter() - started < 60


def test_an_interrupted_batch_keeps_finished_meshes_and_saves_no_blend(extension, tmp_path):
    scans = tmp_path / "scans"
    scans.mkdir()
    for name in ("a", "b"):
        np.savetxt(scans / f"{name}.xyz", sphere_points(20_000, 1.0))
    out = tmp_path / "out"
    process = subprocess.Popen(batch_command(scans, "--output", out, "--resolution", "256",
                                             "--blend", out / "all.blend"),
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    for line in process.stdout:  # wait until the first reconstruction is under way
        if "[1/2] a.xyz:" in line and "%" in line:
            break
    asked = time.perf_counter()
    process.send_signal(signal.SIGINT)
    stdout, stderr = process.communicate(timeout=120)
    print(stdout[-2000:], stderr[-2000:])
    assert time.perf_counter() - asked < 30
    assert process.returncode == 130
    assert "interrupted" in stderr and "Traceback" not in stderr
    assert not (out / "all.blend").exists()
    assert not (out / "a.ply").exists() and not (out / "b.ply").exists()
