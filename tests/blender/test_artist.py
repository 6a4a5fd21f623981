"""What an artist meets (issue 23): where results land, the panel's states, re-runs, the
dependency and GPU checks before any work, and the words in the panel and the Info log.

The panel is drawn into a recording stand-in for ``UILayout``, so the bpy module (no window) can
check what it would show.
"""

import sys
import time

import bpy
import numpy as np
import pytest

from tests.blender.helpers import Drawn, Host, Layout, Reports, add_cloud, sphere_points

RESOLUTION = 32
POINTS = 1000


# What the sidebar shows in full at its default width (longer lines are cut in the middle).
SIDEBAR_CHARACTERS = 30


def draw(extension, cls="ui.panel:UDFR_PT_reconstruct") -> Drawn:
    module, name = cls.split(":")
    log = []
    getattr(extension.module(module), name).draw(Host(Layout(log)), bpy.context)
    drawn = Drawn(log)
    if module == "ui.panel":
        texts = drawn.labels + [entry[2] for entry in log if entry[0] in ("operator", "progress")]
        long = [text for text in texts if text and len(text) > SIDEBAR_CHARACTERS]
        assert not long, f"cut off in the sidebar: {long}"
    return drawn


def poll_message():
    """The message Blender shows when the Reconstruct button is greyed out."""
    assert not bpy.ops.udf_reconstruction.reconstruct.poll()
    with pytest.raises(RuntimeError) as error:
        bpy.ops.udf_reconstruction.reconstruct()
    return str(error.value)


@pytest.fixture(autouse=True)
def no_job_left(extension):
    """A job started by hand and not finished must not block the next test."""
    yield
    extension.module("runtime.job").end_job()


@pytest.fixture
def quick(scene):
    scene.udf_reconstruction.resolution = RESOLUTION
    return scene


@pytest.fixture
def gpu(extension, monkeypatch):
    """Set what the GPU probe says: ``gpu(False)``, ``gpu(True, "name")``."""
    dependencies = extension.module("runtime.dependencies")

    def set_gpu(available, name=""):
        monkeypatch.setitem(dependencies._gpu, "known", True)
        monkeypatch.setitem(dependencies._gpu, "available", available)
        monkeypatch.setitem(dependencies._gpu, "name", name)

    return set_gpu


# --- 3. results land in the source's collection ---------------------------------------------------

def test_result_lands_in_the_child_collection_of_its_source(quick):
    scans = bpy.data.collections.new("Scans")
    quick.collection.children.link(scans)
    site = bpy.data.collections.new("Site A")
    scans.children.link(site)
    cloud = add_cloud("Scan", sphere_points(POINTS, 1.0))
    quick.collection.objects.unlink(cloud)
    site.objects.link(cloud)
    assert bpy.ops.udf_reconstruction.reconstruct() == {'FINISHED'}
    result = bpy.data.objects["Scan_mesh"]
    assert list(result.users_collection) == [site]
    assert result.name in bpy.context.view_layer.objects


def test_result_skips_a_collection_the_view_layer_excludes(quick):
    hidden = bpy.data.collections.new("Excluded")
    shown = bpy.data.collections.new("Shown")
    quick.collection.children.link(hidden)
    quick.collection.children.link(shown)
    cloud = add_cloud("Scan", sphere_points(POINTS, 1.0))
    quick.collection.objects.unlink(cloud)
    hidden.objects.link(cloud)
    shown.objects.link(cloud)
    bpy.context.view_layer.layer_collection.children["Excluded"].exclude = True
    bpy.context.view_layer.objects.active = cloud
    cloud.select_set(True)
    assert bpy.ops.udf_reconstruction.reconstruct() == {'FINISHED'}
    assert list(bpy.data.objects["Scan_mesh"].users_collection) == [shown]


# --- 6. panel states ------------------------------------------------------------------------------

def test_edit_mode_says_to_switch_to_object_mode(quick, extension):
    cloud = add_cloud("Scan", sphere_points(POINTS, 1.0))
    windows = bpy.context.window_manager.windows
    # A windowed Blender's script context has no window: edit mode needs one to show in
    # context.mode, as it does for the user.
    override = {"window": windows[0]} if len(windows) else {}
    with bpy.context.temp_override(**override):
        bpy.ops.object.mode_set(mode='EDIT')
        try:
            assert bpy.context.mode == 'EDIT_MESH'
            assert "Switch to Object Mode" in poll_message()
            assert "Switch to Object Mode" in draw(extension).labels
            assert not any("no points" in text for text in draw(extension).labels)
        finally:
            bpy.ops.object.mode_set(mode='OBJECT')
    assert cloud.mode == 'OBJECT'


def test_a_camera_is_not_a_point_cloud(quick, extension):
    camera = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    quick.collection.objects.link(camera)
    bpy.context.view_layer.objects.active = camera
    camera.select_set(True)
    assert "'Cam' is a camera, not a point cloud" in poll_message()
    drawn = draw(extension)
    assert "Cam: not a point cloud" in drawn.alerts
    assert not any("no points" in text for text in drawn.labels)


def test_nothing_selected_reconstructs_nothing(quick, extension):
    cloud = add_cloud("Scan", sphere_points(POINTS, 1.0))
    cloud.select_set(False)  # Alt+A: the active object stays active, deselected
    assert bpy.context.view_layer.objects.active == cloud
    before = set(bpy.data.objects)
    assert "Nothing is selected" in poll_message()
    assert set(bpy.data.objects) == before
    assert "Nothing selected" in draw(extension).labels
    with pytest.raises(Exception, match="Nothing is selected"):
        extension.module("runtime.job").start_job(bpy.context)  # what invoke() does


def test_after_a_run_the_panel_offers_the_cloud_again_not_the_result(quick, extension):
    add_cloud("Scan", sphere_points(POINTS, 1.0))
    assert draw(extension).button[2] == "Reconstruct"
    assert bpy.ops.udf_reconstruction.reconstruct() == {'FINISHED'}
    result = bpy.context.view_layer.objects.active
    assert result.name == "Scan_mesh"
    drawn = draw(extension)
    assert "Scan_mesh: made from Scan" in drawn.labels
    assert drawn.button[2] == "Reconstruct Again"
    target = extension.module("runtime.bridge").reconstruct_target(bpy.context)
    assert target.source == bpy.data.objects["Scan"], "the cloud, not the result, is meshed"


def test_rerunning_replaces_the_result_instead_of_stacking_copies(quick, extension):
    add_cloud("Scan", sphere_points(POINTS, 1.0))
    assert bpy.ops.udf_reconstruction.reconstruct() == {'FINISHED'}
    first = bpy.data.objects["Scan_mesh"]
    faces = len(first.data.polygons)
    material = bpy.data.materials.new("Clay")
    first.data.materials.append(material)
    meshes = len(bpy.data.meshes)
    quick.udf_reconstruction.radius_mode, quick.udf_reconstruction.radius = "fixed", 0.04
    assert bpy.context.view_layer.objects.active == first  # re-run from the selected result
    assert bpy.ops.udf_reconstruction.reconstruct() == {'FINISHED'}
    assert sorted(o.name for o in bpy.data.objects) == ["Scan", "Scan_mesh"]
    result = bpy.data.objects["Scan_mesh"]
    assert result.data.name == "Scan_mesh"
    assert len(result.data.polygons) not in (0, faces), "the mesh is the new one"
    assert len(bpy.data.meshes) == meshes, "the replaced mesh is removed"
    assert list(result.data.materials) == [material], "the user's material stays"
    assert bpy.context.view_layer.objects.active == result and result.select_get()


def test_rerunning_from_the_cloud_reuses_the_name_and_undoes_in_one_step(quick):
    windows = bpy.context.window_manager.windows
    if not len(windows):
        pytest.skip("no undo stack without a window")
    cloud = add_cloud("Scan", sphere_points(POINTS, 1.0))
    with bpy.context.temp_override(window=windows[0]):
        bpy.ops.ed.undo_push(message="cloud added")
        assert bpy.ops.udf_reconstruction.reconstruct('EXEC_DEFAULT', True) == {'FINISHED'}
        faces = len(bpy.data.objects["Scan_mesh"].data.polygons)
        cloud = bpy.data.objects["Scan"]
        cloud.hide_set(False)
        bpy.data.objects["Scan_mesh"].select_set(False)
        bpy.context.view_layer.objects.active = cloud
        cloud.select_set(True)
        props = bpy.context.scene.udf_reconstruction
        props.radius_mode, props.radius = "fixed", 0.04
        bpy.ops.ed.undo_push(message="settings")
        assert bpy.ops.udf_reconstruction.reconstruct('EXEC_DEFAULT', True) == {'FINISHED'}
        assert sorted(o.name for o in bpy.data.objects) == ["Scan", "Scan_mesh"]
        assert len(bpy.data.objects["Scan_mesh"].data.polygons) != faces
        bpy.ops.ed.undo()
    assert sorted(o.name for o in bpy.data.objects) == ["Scan", "Scan_mesh"]
    assert len(bpy.data.objects["Scan_mesh"].data.polygons) == faces, "the earlier result is back"
    assert not bpy.data.objects["Scan"].hide_get()


def test_a_renamed_result_is_kept(quick):
    add_cloud("Scan", sphere_points(POINTS, 1.0))
    assert bpy.ops.udf_reconstruction.reconstruct() == {'FINISHED'}
    bpy.data.objects["Scan_mesh"].name = "Scan keep"
    assert bpy.ops.udf_reconstruction.reconstruct() == {'FINISHED'}
    assert {"Scan", "Scan keep", "Scan_mesh"} <= {o.name for o in bpy.data.objects}


@pytest.mark.parametrize("hide", [True, False])
def test_the_cloud_is_hidden_after_success_when_asked(quick, extension, hide):
    props = quick.udf_reconstruction
    assert props.bl_rna.properties["hide_source"].default is True, "on by default"
    props.hide_source = hide
    cloud = add_cloud("Scan", sphere_points(POINTS, 1.0))
    assert bpy.ops.udf_reconstruction.reconstruct() == {'FINISHED'}
    assert cloud.hide_get() is hide
    assert draw(extension).prop("hide_source")[3], "the option is in the panel"


def test_a_failed_run_does_not_hide_the_cloud(quick):
    cloud = add_cloud("Three", np.eye(3))
    with pytest.raises(RuntimeError):
        bpy.ops.udf_reconstruction.reconstruct()
    assert not cloud.hide_get()


# --- 1. dependencies, checked before any work -----------------------------------------------------

@pytest.fixture
def missing_package(extension, monkeypatch):
    dependencies = extension.module("runtime.dependencies")
    monkeypatch.setattr(dependencies, "DEPENDENCIES", dependencies.DEPENDENCIES + (
        ("udfr_no_such_module", "NoSuchPackage", "testing", True),))
    return "NoSuchPackage"


def test_a_missing_package_is_reported_before_any_work(quick, extension, monkeypatch,
                                                       missing_package):
    bridge = extension.module("runtime.bridge")
    job = extension.module("runtime.job")

    def no_work(*args, **kwargs):
        raise AssertionError("the points were read although a package is missing")

    monkeypatch.setattr(bridge, "read_point_cloud", no_work)
    monkeypatch.setattr(job, "Job", no_work)
    add_cloud("Scan", sphere_points(20_000, 1.0))
    before = set(bpy.data.objects)
    started = time.perf_counter()
    with pytest.raises(RuntimeError, match="Missing Python package: NoSuchPackage"):
        bpy.ops.udf_reconstruction.reconstruct()
    assert time.perf_counter() - started < 1.0
    assert set(bpy.data.objects) == before
    assert job.running_job() is None


def test_the_panel_names_a_missing_package_in_red(quick, extension, missing_package):
    add_cloud("Scan", sphere_points(POINTS, 1.0))
    assert "Missing package: NoSuchPackage" in draw(extension).alerts


def test_all_present_shows_no_red_line(quick, extension):
    add_cloud("Scan", sphere_points(POINTS, 1.0))
    assert extension.module("runtime.dependencies").missing_packages() == []
    assert not any("Missing" in text for text in draw(extension).labels)


def test_packages_are_named_as_users_install_them(extension):
    dependencies = extension.module("runtime.dependencies")
    reconstruct = extension.module("operators.reconstruct")
    assert dependencies.install_name("skimage.measure") == "scikit-image"
    for module, distribution, _, _ in dependencies.DEPENDENCIES:
        error = ModuleNotFoundError(f"No module named '{module}'", name=module)
        assert reconstruct._missing_dependency(error) == distribution
    reports = Reports()
    reconstruct._report_failure(reports, ModuleNotFoundError("x", name="skimage._shared"))
    ((kind, message),) = reports.messages
    assert kind == {'ERROR'} and "scikit-image" in message and "skimage" not in message


# --- 7. devices -----------------------------------------------------------------------------------

def test_without_a_gpu_cuda_is_greyed_out_and_refused_at_once(quick, extension, gpu,
                                                              monkeypatch):
    gpu(False)
    add_cloud("Scan", sphere_points(POINTS, 1.0))
    drawn = draw(extension)
    assert drawn.enum("cpu")[3] and drawn.enum("auto")[3]
    assert not drawn.enum("cuda")[3], "CUDA is greyed out"
    assert "No GPU: runs on the CPU" in drawn.labels  # Device Auto
    quick.udf_reconstruction.device = "cuda"  # e.g. from a file saved on another machine
    assert "No GPU found" in draw(extension).alerts
    quick.udf_reconstruction.device = "cpu"
    assert not any("GPU" in text for text in draw(extension).labels)
    quick.udf_reconstruction.device = "cuda"
    monkeypatch.setattr(extension.module("runtime.bridge"), "read_point_cloud",
                        lambda *a: pytest.fail("points read before the device was checked"))
    started = time.perf_counter()
    with pytest.raises(RuntimeError, match="No GPU was found.*Set Device to Auto or CPU"):
        bpy.ops.udf_reconstruction.reconstruct()
    assert time.perf_counter() - started < 1.0


def test_with_a_gpu_cuda_is_offered(quick, extension, gpu):
    gpu(True, "Test GPU")
    add_cloud("Scan", sphere_points(POINTS, 1.0))
    drawn = draw(extension)
    assert drawn.enum("cuda")[3]
    assert not any("No GPU" in text for text in drawn.labels)


def test_preferences_do_not_claim_a_gpu_that_is_not_there(extension, gpu):
    gpu(False)
    labels = draw(extension, "ui.preferences:UDFR_AddonPreferences").labels
    assert not any("running on" in text or text.startswith("GPU:") for text in labels)
    assert any("No GPU found" in text for text in labels) or "torch: not found" in labels
    gpu(True, "Test GPU")
    labels = draw(extension, "ui.preferences:UDFR_AddonPreferences").labels
    assert "GPU: Test GPU" in labels or "torch: not found" in labels


def test_the_gpu_probe_agrees_with_torch(extension, monkeypatch):
    dependencies = extension.module("runtime.dependencies")
    monkeypatch.setattr(dependencies, "_gpu", {"known": False, "available": False, "name": "",
                                               "thread": None})
    try:
        import torch
        expected = torch.cuda.is_available()
    except ImportError:
        expected = False
    # The probe must not load torch into Blender's process: it asks a child Python instead.
    monkeypatch.delitem(sys.modules, "torch", raising=False)
    assert dependencies.gpu_available(wait=True) is expected
    assert "torch" not in sys.modules


# --- 4, 5, 8. words -------------------------------------------------------------------------------

def test_progress_is_a_short_stage_name_and_a_percentage(extension):
    wording = extension.module("runtime.wording")
    reconstruct = extension.module("engine.reconstruct").reconstruct
    settings = extension.module("engine.settings").ReconstructSettings(resolution=RESOLUTION)
    seen = []
    reconstruct(sphere_points(POINTS, 1.0), settings,
                progress=lambda fraction, message: seen.append((fraction, message)))
    texts = {wording.progress_text(message, fraction) for fraction, message in seen}
    unknown = {message for _, message in seen if wording.stage_name(message) == "Working"}
    assert not unknown, f"progress messages without a stage name: {unknown}"
    assert max(len(text) for text in texts) <= 16, texts
    assert {"Distances", "Meshing"} <= {text.rsplit(" ", 2)[0] for text in texts}
    assert wording.progress_text("network UDF: 49,152 / 84,297 queries", 0.58) == "Distances 58 %"
    assert wording.progress_text("optimising the cover (80/100)", 0.8) == "Meshing 80 %"
    # in tiles on worker processes the engine counts the tiles, then stitches them
    seen = []
    reconstruct(sphere_points(POINTS, 1.0), dict(resolution=48, tile_cells=24, workers=2),
                progress=lambda fraction, message: seen.append((fraction, message)))
    stages = {wording.stage_name(message) for _, message in seen}
    assert {"Tiles", "Stitching"} <= stages and "Working" not in stages, seen
    assert wording.progress_text("4 of 9 tiles done on 2 workers", 0.37) == "Tiles 37 %"


def finished_job(extension, quick, messages, faces=None):
    """A job run to the end on a small cloud, with the engine's notes replaced by ``messages``."""
    reconstruct = extension.module("operators.reconstruct")
    add_cloud("Scan", sphere_points(POINTS, 1.0))
    job = extension.module("runtime.job").start_job(bpy.context)
    job.run()
    assert job.error is None
    job.result.messages = list(messages)
    if faces is not None:
        job.result.mesh.faces = np.zeros((0, 3), np.int64)
    return reconstruct, job


MESHER_JARGON = [
    "iso raised from 1.00 to 1.25 voxels: the cover was fragmented (104 pieces)",
    "1 component could not be processed (seed regions overlap; unbalanced cut 31642/10570); "
    "kept as extracted",
    "2 components could not be split into one layer (not orientable or non-manifold); kept "
    "double-layered",
]


def test_mesher_jargon_goes_to_the_console_not_the_info_log(quick, extension, capsys):
    reconstruct, job = finished_job(extension, quick, MESHER_JARGON)
    reports = Reports()
    assert reconstruct.finish_job(reports, bpy.context, job) == {'FINISHED'}
    assert [kind for kind, _ in reports.messages] == [{'INFO'}], reports.messages
    assert reports.messages[0][1].startswith("Made 'Scan_mesh': ")
    console = capsys.readouterr().out
    for message in MESHER_JARGON:
        assert message in console


def test_notes_a_user_can_act_on_are_shown_in_plain_words(quick, extension):
    notes = ["dropped 1,234 isolated points (2.5 %) as outliers; set outliers to 'keep' to use "
             "every point",
             "the balls hold only 3.2 points on average; for a cloud this sparse, raise the "
             "radius",
             "kept 20 isolated points (0.25 %): too few to be outliers; set outliers to 'drop' "
             "to remove them",
             "the scan has gaps wider than the ball in places (17 % of the field's nodes lie in "
             "them); turn on Fill Gaps (--fill-gaps) to carry flat "
             "surfaces across them"] + MESHER_JARGON
    quick.udf_reconstruction.radius_mode = "learned"
    reconstruct, job = finished_job(extension, quick, notes)
    reports = Reports()
    reconstruct.finish_job(reports, bpy.context, job)
    warnings = [message for kind, message in reports.messages if kind == {'WARNING'}]
    assert len(warnings) == 4, warnings
    assert "Dropped 1,234 stray points (2.5 %)" in warnings[0]
    assert "Advanced > Outliers to Keep" in warnings[0]
    assert "raise Largest Radius (turn on Custom Range)" in warnings[1]
    assert "Kept 20 stray-looking points (0.25 %)" in warnings[2]
    assert "Advanced > Outliers to Drop" in warnings[2]
    assert "gaps wider than the ball around 17 %" in warnings[3]
    assert "Advanced > Fill Gaps" in warnings[3]
    for _, message in reports.messages:
        assert message[0].isupper() and message.endswith("."), message


def test_one_kept_stray_reads_as_one_point(quick, extension):
    notes = ["kept 1 isolated point (under 0.01 %): too few to be outliers; set outliers to "
             "'drop' to remove them"]
    reconstruct, job = finished_job(extension, quick, notes)
    reports = Reports()
    reconstruct.finish_job(reports, bpy.context, job)
    warnings = [message for kind, message in reports.messages if kind == {'WARNING'}]
    assert warnings and "Kept 1 stray-looking point (under 0.01 %)" in warnings[0], warnings


def test_an_empty_result_is_reported_once(quick, extension):
    reconstruct, job = finished_job(
        extension, quick, ["no surface found",
                           "the mesh is empty: try a larger radius or a lower resolution"],
        faces=0)
    before = set(bpy.data.objects)
    reports = Reports()
    assert reconstruct.finish_job(reports, bpy.context, job) == {'CANCELLED'}
    assert len(reports.messages) == 1, reports.messages
    ((kind, message),) = reports.messages
    assert kind == {'ERROR'} and message.startswith("No surface was found.")
    assert set(bpy.data.objects) == before
    assert not bpy.data.objects["Scan"].hide_get()


def test_engine_refusals_are_reported_as_sentences(quick):
    add_cloud("Three", np.eye(3))
    with pytest.raises(RuntimeError) as error:
        bpy.ops.udf_reconstruction.reconstruct()
    message = str(error.value).split("\n")[0].split(": ", 1)[-1].strip()
    assert message[0].isupper() and message.endswith("."), message


def test_each_mode_shows_its_own_range_until_custom_range_is_on(quick, extension):
    props = quick.udf_reconstruction
    add_cloud("Scan", sphere_points(POINTS, 1.0))  # longest side 2
    props.radius_mode = "learned"
    drawn = draw(extension)
    props_drawn = {entry[1] for entry in drawn.log if entry[0] == "prop"}
    assert "custom_range" in props_drawn and "rho_min" not in props_drawn
    assert "Radius 3 cm to 14.4 cm" in drawn.labels  # 0.015 to 0.072 of 2 m
    props.radius_mode = "curvature"
    assert "Radius 2.4 cm to 4.8 cm" in draw(extension).labels
    props.radius_mode = "learned"
    props.custom_range = True  # starts from the learned range
    assert (props.parent_radius, props.rho_max) == pytest.approx((0.072, 1.0))
    assert props.rho_min == pytest.approx(0.015 / 0.072, abs=1e-6)
    props.rho_min = 0.5
    drawn = draw(extension)
    assert drawn.prop("rho_min")
    assert "Radius 7.2 cm to 14.4 cm" in drawn.labels
    settings = extension.module("ui.properties").to_settings(props)
    assert extension.module("engine.settings").radius_range(settings) == \
        pytest.approx((0.072, 0.5, 1.0))


def test_radius_range_fields_are_labelled_for_artists(quick, extension):
    props = quick.udf_reconstruction
    props.radius_mode = "learned"
    props.custom_range = True
    add_cloud("Scan", sphere_points(POINTS, 1.0))
    drawn = draw(extension)
    assert drawn.prop("rho_min")[2] == "Range Min"
    assert drawn.prop("rho_max")[2] == "Max"
    parent = props.bl_rna.properties["parent_radius"]
    assert parent.name == "Largest Radius"
    assert "parent" not in parent.description.lower()
    for name in ("rho_min", "rho_max"):
        assert "parent" not in props.bl_rna.properties[name].description.lower()


def test_the_running_panel_shows_a_short_progress_text(quick, extension):
    add_cloud("Scan", sphere_points(POINTS, 1.0))
    job = extension.module("runtime.job").start_job(bpy.context)
    job._progress(0.58, "network UDF: 49,152 / 84,297 queries")
    assert job.status_text == "Distances 58 %"
    drawn = draw(extension)
    assert ("progress", "Distances 58 %", None, True) in drawn.log
    job._progress(0.6, "some stage the engine added later")
    assert job.status_text == "Distances 60 %", "an unknown message keeps the last stage"
