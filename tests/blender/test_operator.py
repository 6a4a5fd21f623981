"""The Reconstruct operator on generated clouds: measured quality, placement, colours, refusals,
undo and cancel."""

import time

import bpy
import numpy as np
import pytest
from mathutils import Matrix

from tests.blender.helpers import Reports, add_cloud, scene_state, sphere_points


RADIUS = 0.8          # of the generated sphere, local units
SCALE = 1.5           # object scale: the world sphere has radius RADIUS * SCALE
LOCATION = (1.0, -2.0, 0.5)
RESOLUTION = 64


def colors_at(points):
    """RGBA colours that vary smoothly over the sphere, so carried colours can be checked."""
    rgb = np.clip(0.5 + 0.5 * points / RADIUS, 0.0, 1.0)
    return np.c_[rgb, np.ones(len(points))]


def world_vertices(obj):
    count = len(obj.data.vertices)
    local = np.empty(count * 3, dtype=np.float32)
    obj.data.attributes["position"].data.foreach_get("vector", local)
    matrix = np.array(obj.matrix_world)
    return local.reshape(-1, 3) @ matrix[:3, :3].T + matrix[:3, 3]


@pytest.fixture(scope="module")
def sphere_result(extension):
    """A transformed, coloured 10k-point sphere cloud and what Reconstruct made of it."""
    bpy.ops.wm.read_homefile(use_empty=True)
    scene = bpy.context.scene
    scene.udf_reconstruction.resolution = RESOLUTION
    points = sphere_points(10_000, RADIUS)
    source = add_cloud("Scan", points, colors_at(points))
    source.matrix_world = (Matrix.Translation(LOCATION)
                           @ Matrix.Rotation(0.4, 4, 'X') @ Matrix.Rotation(0.3, 4, 'Z')
                           @ Matrix.Scale(SCALE, 4))
    before = set(bpy.data.objects)
    started = time.perf_counter()
    assert bpy.ops.udf_reconstruction.reconstruct() == {'FINISHED'}
    seconds = time.perf_counter() - started
    (result,) = set(bpy.data.objects) - before
    return source, result, points, seconds


def test_mesh_lies_on_the_true_sphere_and_covers_it(sphere_result):
    from scipy.spatial import cKDTree

    source, result, points, seconds = sphere_result
    vertices = world_vertices(result)
    diameter = 2 * RADIUS * SCALE
    error = np.abs(np.linalg.norm(vertices - np.array(LOCATION), axis=1) - RADIUS * SCALE)
    print(f"sphere: {len(result.data.polygons)} faces in {seconds:.1f} s, distance to the true "
          f"surface mean {error.mean() / diameter:.2e} max {error.max() / diameter:.2e} "
          f"(fractions of the diameter)")
    assert len(result.data.polygons) > 5000
    assert error.mean() < 0.002 * diameter
    assert np.percentile(error, 99) < 0.01 * diameter
    # No holes: every input point has a mesh vertex within two grid cells.
    matrix = np.array(source.matrix_world)
    world_points = points @ matrix[:3, :3].T + matrix[:3, 3]
    gap, _ = cKDTree(vertices).query(world_points)
    assert gap.max() < 2 * diameter / RESOLUTION
    assert not result.data.validate(verbose=False), "the written mesh must be valid as is"


def test_result_sits_on_the_source_selected_and_active(sphere_result):
    source, result, _, _ = sphere_result
    assert result.name == "Scan_mesh"
    assert result.type == 'MESH'
    assert np.allclose(np.array(result.matrix_world), np.array(source.matrix_world), atol=0)
    assert bpy.context.view_layer.objects.active == result
    assert list(bpy.context.view_layer.objects.selected) == [result]
    assert list(result.users_collection) == list(source.users_collection)


def test_point_colours_are_carried_to_the_mesh(sphere_result):
    _, result, _, _ = sphere_result
    attribute = result.data.color_attributes["Col"]
    assert attribute.domain == 'POINT'
    colors = np.empty(len(result.data.vertices) * 4, dtype=np.float32)
    attribute.data.foreach_get("color", colors)
    local = np.empty(len(result.data.vertices) * 3, dtype=np.float32)
    result.data.attributes["position"].data.foreach_get("vector", local)
    expected = colors_at(local.reshape(-1, 3))
    assert np.abs(colors.reshape(-1, 4) - expected).mean() < 0.03


@pytest.mark.parametrize("kind", ["camera", "empty mesh", "no object"])
def test_objects_without_points_are_refused_by_poll(scene, kind):
    if kind == "camera":
        obj = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
        scene.collection.objects.link(obj)
        obj.select_set(True)
        expected = "'Cam' is a camera, not a point cloud: select a mesh or point cloud object"
    elif kind == "empty mesh":
        obj = bpy.data.objects.new("Empty", bpy.data.meshes.new("Empty"))
        scene.collection.objects.link(obj)
        obj.select_set(True)
        expected = "'Empty' has no points"
    else:
        obj = None
        expected = "Select a point cloud first"
    bpy.context.view_layer.objects.active = obj
    assert not bpy.ops.udf_reconstruction.reconstruct.poll()
    with pytest.raises(RuntimeError, match=expected):
        bpy.ops.udf_reconstruction.reconstruct()


def test_three_points_are_refused_with_the_engines_message(scene):
    add_cloud("Three", np.eye(3))
    before = len(bpy.data.objects)
    with pytest.raises(RuntimeError, match="(?i)points"):
        bpy.ops.udf_reconstruction.reconstruct()
    assert len(bpy.data.objects) == before


@pytest.mark.parametrize("mode", ["fixed", "curvature", "learned"])
def test_every_radius_mode_of_the_panel_makes_a_sphere(scene, extension, mode):
    assert set(extension.module("engine.settings").RADIUS_MODES) == {"fixed", "curvature",
                                                                      "learned"}
    add_cloud("Sphere", sphere_points(3000, 1.0))
    scene.udf_reconstruction.radius_mode = mode
    scene.udf_reconstruction.resolution = 32
    assert bpy.ops.udf_reconstruction.reconstruct() == {'FINISHED'}
    vertices = world_vertices(bpy.data.objects["Sphere_mesh"])
    error = np.abs(np.linalg.norm(vertices, axis=1) - 1.0)
    assert len(vertices) > 500 and error.mean() < 0.02, (mode, len(vertices), error.mean())


def test_cancel_button_stops_the_worker_and_changes_nothing(scene, extension):
    reconstruct = extension.module("operators.reconstruct")
    runtime_job = extension.module("runtime.job")
    engine_errors = extension.module("engine.errors")
    add_cloud("Sphere", sphere_points(20_000, 1.0))
    scene.udf_reconstruction.resolution = 128
    before = scene_state()

    job = runtime_job.start_job(bpy.context)  # exactly what invoke() does
    job.start_thread()
    deadline = time.perf_counter() + 30
    while job.fraction == 0.0 and job.running and time.perf_counter() < deadline:
        time.sleep(0.05)
    assert job.running, "the job ended before it could be cancelled"
    assert runtime_job.running_job() is job
    assert not bpy.ops.udf_reconstruction.reconstruct.poll(), "one job at a time"

    asked = time.perf_counter()
    assert bpy.ops.udf_reconstruction.cancel() == {'FINISHED'}  # the panel's Cancel button
    job.thread.join(timeout=10)
    stopped_after = time.perf_counter() - asked
    assert not job.running
    assert stopped_after < 3.0, f"cancelling took {stopped_after:.1f} s"
    assert isinstance(job.error, engine_errors.Cancelled)

    reports = Reports()
    assert reconstruct.finish_job(reports, bpy.context, job) == {'CANCELLED'}
    assert reports.messages == [({'INFO'}, "Reconstruction cancelled; nothing was changed.")]
    assert scene_state() == before
    assert runtime_job.running_job() is None


def test_undo_removes_the_result(scene):
    windows = bpy.context.window_manager.windows
    if not len(windows):
        pytest.skip("no undo stack without a window (bpy module, blender -b); "
                    "`make test-blender-gui` runs this")
    add_cloud("Sphere", sphere_points(3000, 1.0))
    scene.udf_reconstruction.resolution = 32
    with bpy.context.temp_override(window=windows[0]):
        bpy.ops.ed.undo_push(message="cloud added")
        # undo=True: push an undo step as a click on the button does (bpy.ops calls do not)
        assert bpy.ops.udf_reconstruction.reconstruct('EXEC_DEFAULT', True) == {'FINISHED'}
        assert "Sphere_mesh" in bpy.data.objects
        bpy.ops.ed.undo()
    assert "Sphere_mesh" not in bpy.data.objects
    assert "Sphere" in bpy.data.objects
