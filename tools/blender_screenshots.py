"""Screenshots of the N-panel in a real, windowed Blender: idle, running, and with the result.

    xvfb-run -a -s "-screen 0 1600x900x24" blender --factory-startup \\
        --python tools/blender_screenshots.py -- CLOUD_FILE docs/

It drives the real modal path: the Reconstruct operator is invoked as the button does
(``INVOKE_DEFAULT`` in the 3D view), a timer waits for progress and then for the result, ``import
-window root`` (ImageMagick) takes the shots, then Ctrl-Z's operator is run and the result must be
gone. Prints ``SCREENSHOTS OK`` and exits 0 when everything happened, else exits 1.
"""

import importlib
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import addon_utils
import bpy
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "bl_ext.udfr_shots.udf_reconstruction"
cloud_path, out_dir = sys.argv[sys.argv.index("--") + 1:][:2]
OUT = Path(out_dir)
state = {"phase": "setup", "started": time.time()}


def log(message):
    print(f"[screenshots] {message}", flush=True)


def enable_extension():
    parent = Path(tempfile.mkdtemp(prefix="udfr_shots_"))
    (parent / "udf_reconstruction").symlink_to(ROOT, target_is_directory=True)
    bpy.context.preferences.extensions.repos.new(
        name="Screenshots", module="udfr_shots", custom_directory=str(parent), source='USER')
    addon_utils.extensions_refresh(ensure_wheels=False)
    return addon_utils.enable(PACKAGE, default_set=True)


def view3d():
    window = bpy.context.window_manager.windows[0]
    area = next(a for a in window.screen.areas if a.type == 'VIEW_3D')
    region = next(r for r in area.regions if r.type == 'WINDOW')
    return window, area, region


def shot(name):
    path = OUT / name
    subprocess.run(["import", "-window", "root", str(path)], check=True)
    log(f"wrote {path}")


def finish(code):
    sys.stdout.flush()
    os._exit(code)


def setup():
    extension = enable_extension()
    io = importlib.import_module(PACKAGE + ".engine.io")
    geometry = importlib.import_module(PACKAGE + ".engine.geometry")
    bridge = importlib.import_module(PACKAGE + ".operators.bridge")
    assert extension is not None

    for obj in list(bpy.data.objects):
        if obj.type == 'MESH':
            bpy.data.objects.remove(obj)
    cloud = io.read_point_cloud(cloud_path)
    points = cloud.points - cloud.points.mean(axis=0)
    points *= 2.0 / np.ptp(points, axis=0).max()
    height = (points[:, 1] - points[:, 1].min()) / np.ptp(points[:, 1])
    colors = np.c_[0.9 - 0.6 * height, 0.35 + 0.3 * height, 0.2 + 0.7 * height]
    empty = np.zeros((0, 3), dtype=np.int64)
    context = bpy.context
    source = bridge.new_mesh_object(context, geometry.Mesh(points, empty, colors=colors),
                                    "Bunny", np.eye(4))
    source.rotation_euler = (np.pi / 2, 0.0, 0.0)  # the file is y-up
    source.location = (0.0, 0.0, 1.0)

    context.scene.udf_reconstruction.resolution = 96
    context.preferences.view.ui_scale = 1.2
    window, area, region = view3d()
    space = area.spaces.active
    space.show_region_ui = True
    space.shading.color_type = 'VERTEX'  # the active colour attribute
    space.overlay.show_stats = False
    source.select_set(False)  # active is enough; an orange cloud hides the panel's point
    with context.temp_override(window=window, area=area, region=region):
        bpy.ops.view3d.view_selected()
        bpy.ops.ed.undo_push(message="Add cloud")
    log(f"cloud ready: {len(points)} points")


def tick():
    phase = state["phase"]
    if time.time() - state["started"] > 900:
        log("timed out")
        finish(1)
    if phase == "setup":
        setup()
        state["phase"] = "tab"
        return 3.0
    if phase == "tab":
        # Close the splash and open the sidebar's Reconstruct tab (4th tab; factory layout at
        # 1600x900 with a UI scale of 1.2), as a user would.
        subprocess.run(["xdotool", "key", "Escape"], check=True)
        subprocess.run(["xdotool", "mousemove", "1305", "308", "click", "1"], check=True)
        subprocess.run(["xdotool", "mousemove", "700", "450"], check=True)
        state["phase"] = "idle"
        return 2.0
    if phase == "idle":
        shot("blender_panel_idle.png")
        window, area, region = view3d()
        with bpy.context.temp_override(window=window, area=area, region=region):
            # undo=True: like a click on the button, the finished operator pushes an undo step
            result = bpy.ops.udf_reconstruction.reconstruct('INVOKE_DEFAULT', True)
        log(f"invoke -> {result}")
        if result != {'RUNNING_MODAL'}:
            finish(1)
        state["phase"] = "running"
        return 0.5
    job = importlib.import_module(PACKAGE + ".operators.reconstruct").running_job()
    if phase == "running":
        if job is not None and job.fraction >= 0.3:
            time.sleep(0.3)  # let the 0.1 s timer redraw the panel with this progress
            shot("blender_panel_running.png")
            log(f"running shot at {job.fraction:.0%}: {job.message}")
            state["phase"] = "wait"
        elif job is None:
            log("the job ended before the running shot")
            finish(1)
        return 0.2
    if phase == "wait":
        if job is not None:
            return 0.5
        if "Bunny_mesh" not in bpy.data.objects:
            log("no result object")
            finish(1)
        bpy.data.objects["Bunny"].hide_set(True)
        state["phase"] = "result"
        return 1.0
    if phase == "result":
        shot("blender_result.png")
        bpy.data.objects["Bunny"].hide_set(False)
        window, area, region = view3d()
        with bpy.context.temp_override(window=window, area=area, region=region):
            bpy.ops.ed.undo()  # one step: Reconstruct
        gone = "Bunny_mesh" not in bpy.data.objects and "Bunny" in bpy.data.objects
        log(f"after undo the result is {'gone' if gone else 'still there'}")
        log("SCREENSHOTS OK" if gone else "undo failed")
        finish(0 if gone else 1)
    return None


def guarded_tick():
    try:
        return tick()
    except Exception:
        import traceback
        traceback.print_exc()
        finish(1)  # a timer that raises is dropped silently and Blender would stay open


bpy.app.timers.register(guarded_tick, first_interval=2.0)
