"""Screenshots of the N-panel in a real, windowed Blender: idle, running, and with the result.

    xvfb-run -a -s "-screen 0 1600x900x24" blender --factory-startup \\
        --python tools/blender_screenshots.py -- CLOUD_FILE docs/ [RESOLUTION]
        [--detail auto|resolution] [--tile-cells N] [--z-up] [--keep-units] [--prefix blender_]
        [--timeout 900]

``--detail auto`` keeps the panel's default detail (finer cells for a dense cloud) instead of
exactly RESOLUTION cells; ``--tile-cells`` sets Tile Size (forces tiles); ``--z-up`` for a cloud
stored z-up (the default turns a y-up file upright); ``--keep-units`` keeps the cloud's size
(the default scales it to 2 units); ``--prefix`` names the shots
``PREFIX{panel_idle,panel_running,result}.png``.

It drives the real modal path: the Reconstruct operator is invoked as the button does
(``INVOKE_DEFAULT`` in the 3D view), a timer waits for progress and then for the result, ``import
-window root`` (ImageMagick) takes the shots, then Ctrl-Z's operator is run and the result must be
gone. Prints ``SCREENSHOTS OK`` and exits 0 when everything happened, else exits 1.

What makes the shots read well (each was a problem once):
- the splash is switched off in the preferences before Blender shows it (``--python`` runs first);
- the 3D view is maximized (Ctrl+Space) and the sidebar is opened on the "Reconstruct" tab through
  ``Region.active_panel_category``, not by clicking (Xvfb has no window manager, so synthetic
  keys and clicks are unreliable);
- the cloud stays selected: a mesh of loose vertices is drawn only as points in Object Mode, black
  when unselected (invisible on the dark grid), orange when selected; the theme's vertex size
  makes the points larger;
- for the result the cloud is hidden and the mesh is shown in Solid mode with a studio light.
"""

import argparse
import importlib
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import addon_utils
import bpy
import numpy as np
from mathutils import Euler

sys.path.insert(0, str(Path(__file__).resolve().parent))
from blender_window import finish, screenshot, sidebar, view3d  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "bl_ext.udfr_shots.udf_reconstruction"
PARSER = argparse.ArgumentParser(prog="blender_screenshots.py")
PARSER.add_argument("cloud")
PARSER.add_argument("out_dir")
PARSER.add_argument("resolution", nargs="?", type=int, default=96)
PARSER.add_argument("--detail", choices=("auto", "resolution"), default="resolution")
PARSER.add_argument("--tile-cells", type=int, default=0)
PARSER.add_argument("--z-up", action="store_true")
PARSER.add_argument("--keep-units", action="store_true")
PARSER.add_argument("--prefix", default="blender_")
PARSER.add_argument("--timeout", type=float, default=900.0)
ARGS = PARSER.parse_args(sys.argv[sys.argv.index("--") + 1:])
cloud_path = ARGS.cloud
RESOLUTION = ARGS.resolution
OUT = Path(ARGS.out_dir)
NAME = "Cloud"
state = {"phase": "setup", "started": time.time()}

# Before Blender opens its first window: no splash (it would cover every shot), larger UI text.
bpy.context.preferences.view.show_splash = False
bpy.context.preferences.view.ui_scale = 1.25
bpy.context.preferences.themes[0].view_3d.vertex_size = 2


def log(message):
    print(f"[screenshots] {message}", flush=True)


def enable_extension():
    parent = Path(tempfile.mkdtemp(prefix="udfr_shots_"))
    (parent / "udf_reconstruction").symlink_to(ROOT, target_is_directory=True)
    bpy.context.preferences.extensions.repos.new(
        name="Screenshots", module="udfr_shots", custom_directory=str(parent), source='USER')
    addon_utils.extensions_refresh(ensure_wheels=False)
    return addon_utils.enable(PACKAGE, default_set=True)


def shot(name):
    path = OUT / name
    screenshot(path)
    log(f"wrote {path}")


def setup():
    extension = enable_extension()
    io = importlib.import_module(PACKAGE + ".engine.io")
    geometry = importlib.import_module(PACKAGE + ".engine.geometry")
    bridge = importlib.import_module(PACKAGE + ".runtime.bridge")
    assert extension is not None

    for obj in list(bpy.data.objects):  # the factory cube, camera and light
        bpy.data.objects.remove(obj)
    cloud = io.read_point_cloud(cloud_path)
    points = cloud.points - cloud.points.mean(axis=0)
    if not ARGS.keep_units:
        points *= 2.0 / np.ptp(points, axis=0).max()
    empty = np.zeros((0, 3), dtype=np.int64)
    context = bpy.context
    source = bridge.new_mesh_object(context, geometry.Mesh(points, empty), NAME, np.eye(4))
    if not ARGS.z_up:
        source.rotation_euler = (np.pi / 2, 0.0, 0.0)  # the file is y-up
    source.location = (0.0, 0.0, 0.5 * np.ptp(points[:, 2]) if ARGS.z_up else 1.0)
    context.view_layer.objects.active = source
    source.select_set(True)  # selected loose vertices are drawn orange; unselected, black

    props = context.scene.udf_reconstruction
    props.resolution = RESOLUTION
    props.detail = ARGS.detail
    if ARGS.tile_cells:
        props.tile_cells = ARGS.tile_cells
    window, area, region = view3d()
    with context.temp_override(window=window, area=area, region=region):
        bpy.ops.screen.screen_full_area()  # Ctrl+Space: the 3D view fills the window
    window, area, region = view3d()
    space = area.spaces.active
    space.show_region_ui = True
    space.shading.type = 'SOLID'
    space.shading.light = 'STUDIO'
    space.shading.color_type = 'MATERIAL'
    space.overlay.show_stats = False
    space.overlay.show_floor = True
    with context.temp_override(window=window, area=area, region=region):
        view = space.region_3d
        view.view_perspective = 'PERSP'
        view.view_rotation = Euler((np.radians(72), 0.0, np.radians(35))).to_quaternion()
        bpy.ops.view3d.view_selected()
        bpy.ops.ed.undo_push(message="Add cloud")
    log(f"cloud ready: {len(points):,} points, detail {ARGS.detail}, resolution {RESOLUTION}, "
        f"tile cells {props.tile_cells}")


def open_tab():
    region = sidebar()
    region.active_panel_category = "Reconstruct"
    view3d()[1].tag_redraw()
    log(f"sidebar tab: {region.active_panel_category}")
    return region.active_panel_category == "Reconstruct"


def tick():
    phase = state["phase"]
    if time.time() - state["started"] > ARGS.timeout:
        log("timed out")
        finish(1)
    if phase == "setup":
        setup()
        state["phase"] = "tab"
        return 1.0
    if phase == "tab":
        if not open_tab():
            log("could not open the Reconstruct tab")
            finish(1)
        # Out of the way (no hover highlight). The sidebar keeps its default width: dragging its
        # edge with xdotool did not resize it, so the progress bar's long stage text is elided
        # in the middle; the status bar shows it in full.
        subprocess.run(["xdotool", "mousemove", "10", "890"], check=False)
        state["phase"] = "idle"
        return 2.0
    if phase == "idle":
        shot(f"{ARGS.prefix}panel_idle.png")
        window, area, region = view3d()
        with bpy.context.temp_override(window=window, area=area, region=region):
            # undo=True: like a click on the button, the finished operator pushes an undo step
            result = bpy.ops.udf_reconstruction.reconstruct('INVOKE_DEFAULT', True)
        log(f"invoke -> {result}")
        if result != {'RUNNING_MODAL'}:
            finish(1)
        state["phase"] = "running"
        return 0.5
    job = importlib.import_module(PACKAGE + ".runtime.job").running_job()
    if phase == "running":
        if job is not None and job.fraction >= 0.3:
            time.sleep(0.3)  # let the 0.1 s timer redraw the panel with this progress
            shot(f"{ARGS.prefix}panel_running.png")
            log(f"running shot at {job.fraction:.0%}: {job.message}")
            state["phase"] = "wait"
        elif job is None:
            log("the job ended before the running shot")
            finish(1)
        return 0.2
    if phase == "wait":
        if job is not None:
            return 0.5
        result = bpy.data.objects.get(NAME + "_mesh")
        if result is None:
            log("no result object")
            finish(1)
        log(f"result: {len(result.data.polygons):,} faces")
        bpy.data.objects[NAME].hide_set(True)
        state["phase"] = "result"
        return 1.5
    if phase == "result":
        shot(f"{ARGS.prefix}result.png")
        bpy.data.objects[NAME].hide_set(False)
        window, area, region = view3d()
        with bpy.context.temp_override(window=window, area=area, region=region):
            bpy.ops.ed.undo()  # one step: Reconstruct
        gone = NAME + "_mesh" not in bpy.data.objects and NAME in bpy.data.objects
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
