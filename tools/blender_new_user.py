"""The "new user" flow in a real, windowed Blender: install the zip, import a PLY, reconstruct.

    make check-new-user \
    BLENDER="../shared/tools/real-blender/shell.sh xvfb-run -a -s '-screen 0 1600x900x24' blender"

or by hand, with a throw-away user configuration (the script refuses to run without one):

    make build-lean
    BLENDER_USER_RESOURCES=$PWD/.cache/blender-newuser xvfb-run -a -s "-screen 0 1600x900x24" \\
        blender --factory-startup --python-exit-code 1 --python tools/blender_new_user.py -- \\
        dist/udf_reconstruction-0.1.0.zip CLOUD.ply SHOT_DIR [RESOLUTION]

What a user does, step by step, each checked and printed as ``[new-user] step N: ...``:

1. the zip exists (``make build-lean`` made it);
2. it is installed as *Install from Disk...* does (``extensions.package_install_files`` into the
   ``user_default`` repository, enabled on install); the add-on must be enabled from the user
   configuration and the 3D view's sidebar must have the "Reconstruct" tab;
3. the PLY is imported with Blender's own importer (*File > Import > Stanford PLY*) and must be
   the active object, a mesh of vertices only;
4. Reconstruct is invoked as the button does (``INVOKE_DEFAULT`` in the 3D view, with an undo
   push), and once the progress is above 0 the panel's Cancel button (``udf_reconstruction.
   cancel``, invoked in the sidebar) stops it: within 2 s the job must be over, reported as
   cancelled, with no object or mesh added;
5. Reconstruct again, to the end: a new ``<name>_mesh`` object with faces, on the cloud's world
   matrix, selected and active; screenshots of the run and the result go to SHOT_DIR;
6. one undo (Ctrl+Z's operator) removes the result and keeps the cloud.

Prints ``NEW USER FLOW OK`` and exits 0 when all of that held, else exits 1. It is driven by a
``bpy.app.timers`` function (``--python`` runs before the window exists) and ends with
``os._exit``, as ``tools/blender_screenshots.py`` does.
"""

import importlib
import os
import sys
import time
from pathlib import Path

import addon_utils
import bpy

sys.path.insert(0, str(Path(__file__).resolve().parent))
from blender_window import (Failed, check, finish, guarded, log, shot, sidebar,  # noqa: E402
                            start_flow, view3d)

ZIP, CLOUD, RESOLUTION = start_flow("blender_new_user.py", "new-user", 64)
EXTENSION_ID = "udf_reconstruction"
PACKAGE = f"bl_ext.user_default.{EXTENSION_ID}"
TAB = "Reconstruct"
CANCEL_WITHIN = 2.0  # seconds from the Cancel click to the job being over
TIME_LIMIT = 900.0   # the whole flow

bpy.context.preferences.view.show_splash = False  # before the first window is drawn
state = {"phase": "start", "started": time.time()}


def in_view3d():
    window, area, region = view3d()
    return bpy.context.temp_override(window=window, area=area, region=region)


def running_job():
    return importlib.import_module(PACKAGE + ".runtime.job").running_job()


def datablocks():
    return set(bpy.data.objects.keys()), set(bpy.data.meshes.keys())


# -- the steps ----------------------------------------------------------------------------------

def step_zip():
    user = os.environ.get("BLENDER_USER_RESOURCES")
    check(user, "BLENDER_USER_RESOURCES is not set: this script installs an extension and must "
                "not touch your own Blender configuration")
    check(bpy.context.window_manager.windows, "no window: run it without -b (under xvfb-run)")
    check(ZIP.is_file(), f"{ZIP} is missing (make build-lean)")
    check(CLOUD.is_file(), f"{CLOUD} is missing")
    check(PACKAGE not in bpy.context.preferences.addons, "the extension is already enabled")
    log(f"step 1: zip {ZIP.name} ({ZIP.stat().st_size / 1e6:.1f} MB), Blender "
        f"{bpy.app.version_string}, Python {sys.version.split()[0]}, user config {user}")


def step_install():
    window = bpy.context.window_manager.windows[0]
    with bpy.context.temp_override(window=window):
        result = bpy.ops.extensions.package_install_files(
            filepath=str(ZIP), repo='user_default', enable_on_install=True)
    check(result == {'FINISHED'}, f"package_install_files -> {result}")
    check(PACKAGE in bpy.context.preferences.addons, f"{PACKAGE} is not enabled after install")
    module = sys.modules.get(PACKAGE)
    check(module is not None, f"{PACKAGE} was not imported")
    installed = Path(bpy.utils.user_resource('EXTENSIONS')).resolve() / "user_default"
    where = Path(module.__file__).resolve()
    check(installed in where.parents, f"the add-on runs from {where}, not from {installed}")
    check(os.path.realpath(os.environ["BLENDER_USER_RESOURCES"]) in str(where),
          "the add-on is not in the throw-away user configuration")
    loaded_default, loaded_state = addon_utils.check(PACKAGE)
    check(loaded_state, "addon_utils says the add-on is not loaded")
    panel = getattr(bpy.types, "UDFR_PT_reconstruct", None)
    check(panel is not None and panel.bl_category == TAB, "the Reconstruct panel is not registered")
    check(hasattr(bpy.types.Scene, "udf_reconstruction"), "the scene settings are not registered")
    _, area, _ = view3d()
    area.spaces.active.show_region_ui = True  # N: the sidebar opens; its tabs show next redraw
    area.tag_redraw()
    log(f"step 2: installed and enabled from {where.parent}")


def step_tab():
    region = sidebar()
    try:
        region.active_panel_category = TAB  # clicking the tab
    except (TypeError, ValueError) as error:
        raise Failed(f"the sidebar has no '{TAB}' tab: {error}")
    check(region.active_panel_category == TAB,
          f"the sidebar shows '{region.active_panel_category}', not '{TAB}'")
    view3d()[1].tag_redraw()
    log(f"step 2: sidebar tab '{region.active_panel_category}' is there and open")


def step_import():
    objects_before, _ = datablocks()
    with in_view3d():
        # undo=True: *File > Import* pushes an undo step; the undo in step 6 comes back to here
        result = bpy.ops.wm.ply_import('EXEC_DEFAULT', True, filepath=str(CLOUD))
    check(result == {'FINISHED'}, f"ply_import -> {result}")
    new = set(bpy.data.objects.keys()) - objects_before
    check(len(new) == 1, f"the import added {sorted(new)}")
    source = bpy.data.objects[new.pop()]
    check(source.type == 'MESH', f"the import made a {source.type}")
    check(bpy.context.view_layer.objects.active == source, "the imported cloud is not active")
    check(len(source.data.vertices) > 0 and len(source.data.polygons) == 0,
          "expected a mesh of vertices only")
    state["source"] = source.name
    colours = [a.name for a in source.data.color_attributes]
    log(f"step 3: imported '{source.name}': {len(source.data.vertices):,} vertices, 0 faces, "
        f"colour attributes {colours}")
    settings = bpy.context.scene.udf_reconstruction
    settings.resolution = RESOLUTION  # typed into the panel's Resolution field
    with in_view3d():
        bpy.ops.view3d.view_selected()


def invoke_reconstruct():
    with in_view3d():
        # as a click on the button: INVOKE_DEFAULT in the 3D view, undo=True
        result = bpy.ops.udf_reconstruction.reconstruct('INVOKE_DEFAULT', True)
    check(result == {'RUNNING_MODAL'}, f"Reconstruct -> {result} (expected RUNNING_MODAL)")
    job = running_job()
    check(job is not None, "no job is running after the click")
    return job


def click_cancel():
    window, area, _ = view3d()
    with bpy.context.temp_override(window=window, area=area, region=sidebar()):
        # the ✕ next to the progress bar (ui/panel.py): this operator, invoked from the sidebar
        result = bpy.ops.udf_reconstruction.cancel('INVOKE_DEFAULT')
    check(result == {'FINISHED'}, f"Cancel -> {result}")


def check_result():
    name = state["source"] + "_mesh"
    result = bpy.data.objects.get(name)
    check(result is not None, f"no object '{name}' after the run "
                              f"(objects: {sorted(bpy.data.objects.keys())})")
    source = bpy.data.objects[state["source"]]
    faces = len(result.data.polygons)
    check(faces > 0, f"'{name}' has no faces")
    same = all(result.matrix_world[i][j] == source.matrix_world[i][j]
               for i in range(4) for j in range(4))
    check(same, f"matrix_world differs:\n{result.matrix_world}\nvs\n{source.matrix_world}")
    check(result.select_get(), f"'{name}' is not selected")
    check(bpy.context.view_layer.objects.active == result, f"'{name}' is not active")
    colours = [a.name for a in result.data.color_attributes]
    log(f"step 5: '{name}': {len(result.data.vertices):,} vertices, {faces:,} faces, "
        f"same matrix_world as '{source.name}', selected and active, colours {colours}, "
        f"{state['run_seconds']:.1f} s")
    source.hide_set(True)  # for the screenshot: the surface, not the points over it
    space = view3d()[1].spaces.active
    space.shading.type = 'SOLID'
    if colours:  # Viewport Shading > Color > Attribute (called Vertex up to Blender 4.3)
        kinds = {item.identifier for item in
                 space.shading.bl_rna.properties["color_type"].enum_items}
        space.shading.color_type = 'ATTRIBUTE' if 'ATTRIBUTE' in kinds else 'VERTEX'
    with in_view3d():
        bpy.ops.view3d.view_selected()


def step_undo():
    bpy.data.objects[state["source"]].hide_set(False)
    window = bpy.context.window_manager.windows[0]
    with bpy.context.temp_override(window=window):
        result = bpy.ops.ed.undo()  # Ctrl+Z, once
    check(result == {'FINISHED'}, f"undo -> {result}")
    name = state["source"] + "_mesh"
    check(name not in bpy.data.objects, f"'{name}' is still there after one undo")
    check(state["source"] in bpy.data.objects, f"'{state['source']}' is gone after the undo")
    check(PACKAGE in bpy.context.preferences.addons, "the undo disabled the add-on")
    log(f"step 6: one undo removed '{name}'; '{state['source']}' is still there")


# -- the phases, one per timer call ---------------------------------------------------------------

def tick():
    phase = state["phase"]
    now = time.time()
    check(now - state["started"] < TIME_LIMIT, f"timed out in phase '{phase}'")
    if phase == "start":
        step_zip()
        step_install()
        state["phase"] = "tab"
        return 1.0
    if phase == "tab":
        step_tab()
        step_import()
        state["phase"] = "first run"
        return 1.0
    if phase == "first run":
        state["before"] = datablocks()
        state["job"] = invoke_reconstruct()
        state["phase"] = "wait progress"
        state["since"] = now
        log("step 4: Reconstruct clicked -> RUNNING_MODAL")
        return 0.05
    if phase == "wait progress":
        job = state["job"]
        if job.fraction <= 0.0:
            check(job.running, f"the job ended before any progress (error: {job.error!r})")
            check(now - state["since"] < 120, "no progress after 120 s")
            return 0.05
        check(job.running, "the job ended before it could be cancelled (raise the resolution)")
        log(f"step 4: progress {job.fraction:.0%} ({job.message}) after "
            f"{now - state['since']:.1f} s")
        click_cancel()
        state["asked"] = time.time()
        state["phase"] = "wait cancel"
        return 0.05
    if phase == "wait cancel":
        job = state["job"]
        over = not job.running and running_job() is None
        waited = now - state["asked"]
        if not over:
            check(waited < CANCEL_WITHIN, f"the job was still running {waited:.1f} s after "
                                          f"Cancel (stage: {job.message})")
            return 0.05
        errors = importlib.import_module(PACKAGE + ".engine.errors")
        check(isinstance(job.error, errors.Cancelled), f"the job ended with {job.error!r}")
        check(datablocks() == state["before"],
              f"cancelling left datablocks behind: {datablocks()} vs {state['before']}")
        log(f"step 4: cancelled; the job was over {waited:.2f} s after Cancel, no object or mesh "
            f"was added")
        state["phase"] = "second run"
        return 0.5
    if phase == "second run":
        check(bpy.ops.udf_reconstruction.reconstruct.poll(), "Reconstruct is greyed out")
        state["job"] = invoke_reconstruct()
        state["since"] = now
        state["phase"] = "wait result"
        state["shot running"] = False
        log("step 5: Reconstruct clicked again")
        return 0.2
    if phase == "wait result":
        job = state["job"]
        if running_job() is not None:
            check(now - state["since"] < 600, "no result after 600 s")
            if not state["shot running"] and job.fraction >= 0.3:
                state["shot running"] = True
                shot("new_user_running.png")
            return 0.2
        check(job.error is None, f"the run failed: {job.error!r}")
        state["run_seconds"] = now - state["since"]
        check_result()
        state["phase"] = "result shot"
        return 1.5
    if phase == "result shot":
        shot("new_user_result.png")
        step_undo()
        log("NEW USER FLOW OK")
        finish(0)
    return None


bpy.app.timers.register(guarded(tick, lambda: f" ({state['phase']})"),
                        first_interval=2.0)
