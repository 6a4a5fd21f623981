"""The artist's checks of issue 23, clicked through a real Blender's UI with xdotool.

    make check-ui \\
    BLENDER="../shared/tools/real-blender/shell.sh xvfb-run -a -s '-screen 0 1600x900x24' blender"

or by hand, in a throw-away user configuration of a windowed Blender whose Python lacks scipy
and scikit-image (the script refuses to run otherwise), with xdotool and ImageMagick's
``import`` on the PATH:

    BLENDER_USER_RESOURCES=$PWD/.cache/blender-ui xvfb-run -a -s "-screen 0 1600x900x24" \\
        blender --factory-startup --python-exit-code 1 --python tools/blender_ui_check.py -- \\
        dist/udf_reconstruction-0.1.0.zip CLOUD.ply SHOT_DIR [RESOLUTION]

Every click is a real X event (``xdotool click``) on a button found on screen: the mouse is
moved down the panel and Ctrl+C tells which button is under it (over an operator button it
copies the button's Python command). Steps, each printed as ``[ui-check] ...``:

1. the lean zip is installed and enabled (as *Install from Disk...* does); scipy and
   scikit-image are missing;
2. a cloud is selected and **Reconstruct** clicked: the missing packages are reported within a
   second, before any work, and nothing is added (``ui_missing_package.png``);
3. Preferences > Add-ons > UDF Reconstruction: **Install Missing Packages** clicked; pip runs
   with a progress bar and the page says what was installed (``ui_install_packages.png``);
4. without a restart, the cloud (now inside a child collection "Scans") is reconstructed by a
   click, and the result lands in "Scans" (``ui_child_collection.png``);
5. CLOUD (a PLY) is imported with Blender's importer and reconstructed by a click at RESOLUTION
   (default 128); every message of the run in the Info log is one a user can act on
   (``ui_real_scan.png``).

Prints ``UI CHECK OK`` and exits 0 when all of that held, else exits 1.
"""

import importlib
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import bpy

sys.path.insert(0, str(Path(__file__).resolve().parent))
from blender_window import (Failed, check, finish, guarded, log, shot, sidebar,  # noqa: E402
                            start_flow, view3d)

ZIP, CLOUD, RESOLUTION = start_flow("blender_ui_check.py", "ui-check", 128)
PACKAGE = "bl_ext.user_default.udf_reconstruction"
REPORT_WITHIN = 1.0  # seconds from the click to the missing-package report
# The words of the mesher's own diagnostics, which belong in the console, not the Info log.
JARGON = re.compile(r"(?i)\biso\b|voxel|cover|seed region|unbalanced|cut \d|twin|handles|"
                    r"fragmented|queries|band")

bpy.context.preferences.view.show_splash = False


def module(name):
    return importlib.import_module(f"{PACKAGE}.{name}")


def xdotool(*args):
    subprocess.run(["xdotool", *map(str, args)], check=True)


def screen_point(window, region, x, y):
    """X screen coordinates of the point (x, y) of ``region`` (Blender counts y upwards)."""
    return window.x + region.x + x, window.y + window.height - (region.y + y)


def find_button(window, region, command):
    """Move the mouse down the middle of ``region``, pressing Ctrl+C at each stop, until the
    clipboard names ``command`` (an operator button copies its Python command); yields waits,
    returns the point."""
    wm = bpy.context.window_manager
    for y in range(region.height - 12, 8, -8):
        wm.clipboard = ""
        point = screen_point(window, region, region.width // 2, y)
        xdotool("mousemove", *point)
        xdotool("key", "ctrl+c")
        yield 0.06
        if command in wm.clipboard:
            return point
    raise Failed(f"no button for {command} in the {region.type} region")


def click(point):
    xdotool("mousemove", *point)
    xdotool("click", "1")


def info_area():
    """The Info editor: the timeline at the bottom becomes one, so the screenshots show the
    messages too."""
    window = bpy.context.window_manager.windows[0]
    for area in window.screen.areas:
        if area.type == 'INFO':
            return area
    area = min((a for a in window.screen.areas if a.type == 'DOPESHEET_EDITOR'),
               key=lambda a: a.y)
    area.type = 'INFO'
    return area


def reports():
    """The Info log's reports so far, one line each (selected and copied, as Ctrl+C there
    does)."""
    window = bpy.context.window_manager.windows[0]
    area = info_area()
    region = next(r for r in area.regions if r.type == 'WINDOW')
    wm = bpy.context.window_manager
    with bpy.context.temp_override(window=window, area=area, region=region):
        bpy.ops.info.select_all(action='SELECT')
        wm.clipboard = ""
        bpy.ops.info.report_copy()
        bpy.ops.info.select_all(action='DESELECT')
    # The log also lists the operators that ran ("bpy.ops...."): those are not messages.
    return [line for line in wm.clipboard.splitlines()
            if line.strip() and not line.startswith("bpy.")]


def sphere_cloud(name, count=20_000):
    import numpy as np  # after the install: this Blender may not have numpy yet

    i = np.arange(count) + 0.5
    polar, azimuth = np.arccos(1 - 2 * i / count), np.pi * (1 + 5 ** 0.5) * i
    points = np.c_[np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar),
                   np.cos(polar)]
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(count)
    mesh.vertices.foreach_set("co", points.astype(np.float32).ravel())
    return bpy.data.objects.new(name, mesh)


def select_only(obj):
    layer = bpy.context.view_layer
    for other in layer.objects:
        if other is not None:  # None: removed from Python, not yet caught up by the layer
            other.select_set(False)
    obj.select_set(True)
    layer.objects.active = obj


def wait_for_job(limit):
    """Yield waits until the reconstruction started by a click is over."""
    job = module("runtime.job")
    started = time.time()
    while job.running_job() is None and time.time() - started < 5:
        yield 0.1  # the click is processed at the next event
    while job.running_job() is not None:
        check(time.time() - started < limit, f"no result after {limit} s")
        yield 0.5
    yield 1.0  # the result is drawn


def flow():
    wm = bpy.context.window_manager
    window = wm.windows[0]
    user = os.environ.get("BLENDER_USER_RESOURCES")
    check(user, "BLENDER_USER_RESOURCES is not set: this script installs an extension and must "
                "not touch your own Blender configuration")
    check(ZIP.is_file() and CLOUD.is_file(), f"missing {ZIP} or {CLOUD}")
    with bpy.context.temp_override(window=window):
        result = bpy.ops.extensions.package_install_files(
            filepath=str(ZIP), repo='user_default', enable_on_install=True)
    check(result == {'FINISHED'} and PACKAGE in bpy.context.preferences.addons,
          f"installing {ZIP.name} -> {result}")
    missing = module("runtime.dependencies").missing_packages()
    check("scipy" in missing, f"this check needs a Blender without scipy (missing: {missing})")
    log(f"step 1: {ZIP.name} installed and enabled in Blender {bpy.app.version_string} "
        f"(Python {sys.version.split()[0]}); missing: {', '.join(missing)}")
    yield 1.0

    # 2. a missing package is reported at the click, before any work
    _, area, _ = view3d()
    area.spaces.active.show_region_ui = True
    area.tag_redraw()
    yield 1.0
    panel = sidebar()
    panel.active_panel_category = "Reconstruct"
    cube = bpy.data.objects.get("Cube")  # the startup cube would hide the sphere's mesh
    if cube is not None:
        bpy.data.objects.remove(cube)
    numpy_found = module("runtime.dependencies").is_found("numpy")
    if numpy_found:
        cloud = sphere_cloud("Sphere")
        bpy.context.scene.collection.objects.link(cloud)
        select_only(cloud)
    area.tag_redraw()
    yield 1.0
    if numpy_found:
        button = yield from find_button(window, panel, "udf_reconstruction.reconstruct")
        before = set(bpy.data.objects.keys())
        reconstruct = module("operators.reconstruct")
        checked = []  # (start, end) of the button's dependency check
        dependency_check = reconstruct._check_dependencies

        def timed_check(operator):
            started = time.time()
            refused = dependency_check(operator)
            checked.append((started, time.time()))
            return refused

        reconstruct._check_dependencies = timed_check
        yield 0.5  # the view is drawn after the probing
        clicked = time.time()
        click(button)
        while not any("Missing Python package" in r for r in reports()):
            check(time.time() - clicked < 5, "no report within 5 s of the click")
            yield 0.05
        reconstruct._check_dependencies = dependency_check
        check(checked, "the click did not reach the operator")
        (started, refused), = checked
        check(refused - started < REPORT_WITHIN, f"the check took {refused - started:.2f} s")
        check(set(bpy.data.objects.keys()) == before, "the failed click added objects")
        log(f"step 2: clicked Reconstruct: Blender passed the click to the operator "
            f"{started - clicked:.2f} s later, which refused it in "
            f"{1000 * (refused - started):.0f} ms, before reading any point: "
            f"{[r for r in reports() if 'Missing' in r][-1]}")
        yield 0.5
        shot("ui_missing_package.png")
    else:
        log("step 2: skipped: this Blender has no numpy, so the Reconstruct tab appears only "
            "after the install")

    # 3. Preferences > Add-ons > UDF Reconstruction > Install Missing Packages
    prefs_area = area  # the 3D view shows the preferences for a while: room for the page
    prefs_area.type = 'PREFERENCES'
    bpy.context.preferences.active_section = 'ADDONS'
    wm.addon_search = "UDF"
    with bpy.context.temp_override(window=window, area=prefs_area):
        bpy.ops.preferences.addon_expand(module=PACKAGE)
    yield 1.0
    region = next(r for r in prefs_area.regions if r.type == 'WINDOW')
    button = yield from find_button(window, region, "udf_reconstruction.install_packages")
    click(button)
    installer = module("runtime.installer")
    started = time.time()
    while installer.running_install() is None and installer.last_result() is None:
        check(time.time() - started < 5, "the install did not start")
        yield 0.1
    shown = False
    while installer.running_install() is not None:
        check(time.time() - started < 900, "the install took over 15 minutes")
        if not shown and installer.running_install().fraction > 0.2:
            shown = True
            shot("ui_install_running.png")
        yield 0.5
    ok, message = installer.last_result()
    log(f"step 3: Install Missing Packages: {message}")
    check(ok, message)
    check(not module("runtime.dependencies").missing_packages(), "still missing packages")
    yield 1.5
    shot("ui_install_packages.png")
    prefs_area.type = 'VIEW_3D'

    # 4. without a restart: a cloud in a child collection gets its result there
    scans = bpy.data.collections.new("Scans")
    bpy.context.scene.collection.children.link(scans)
    cloud = bpy.data.objects.get("Sphere") or sphere_cloud("Sphere")
    for collection in list(cloud.users_collection):
        collection.objects.unlink(cloud)
    scans.objects.link(cloud)
    select_only(cloud)
    bpy.context.scene.udf_reconstruction.resolution = 64
    panel = sidebar()
    panel.active_panel_category = "Reconstruct"
    area.tag_redraw()
    yield 1.0
    button = yield from find_button(window, panel, "udf_reconstruction.reconstruct")
    click(button)
    yield from wait_for_job(600)
    result = bpy.data.objects.get("Sphere_mesh")
    check(result is not None and len(result.data.polygons) > 0,
          f"no result; Info log: {reports()[-3:]}")
    homes = [c.name for c in result.users_collection]
    check(homes == ["Scans"], f"the result is in {homes}, not in Scans")
    log(f"step 4: clicked Reconstruct (no restart): 'Sphere_mesh' with "
        f"{len(result.data.polygons):,} faces, in collection {homes}")
    with bpy.context.temp_override(window=window, area=area,
                                   region=next(r for r in area.regions if r.type == 'WINDOW')):
        bpy.ops.view3d.view_selected()
    yield 1.0
    shot("ui_child_collection.png")

    # 5. a real scan: only messages a user can act on
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    with bpy.context.temp_override(window=window, area=area):
        bpy.ops.wm.ply_import(filepath=str(CLOUD))
    source = bpy.context.view_layer.objects.active
    check(source is not None and len(source.data.vertices) > 0, "the PLY import failed")
    select_only(source)
    bpy.context.scene.udf_reconstruction.resolution = RESOLUTION
    with bpy.context.temp_override(window=window, area=area,
                                   region=next(r for r in area.regions if r.type == 'WINDOW')):
        bpy.ops.view3d.view_selected()
    yield 1.0
    seen = len(reports())
    button = yield from find_button(window, panel, "udf_reconstruction.reconstruct")
    click(button)
    yield from wait_for_job(1800)
    shown = reports()[seen:]
    log(f"step 5: '{source.name}' ({len(source.data.vertices):,} points) at {RESOLUTION}: "
        f"the Info log shows {shown}")
    made = bpy.data.objects.get(source.name + "_mesh")
    check(made is not None and len(made.data.polygons) > 0, f"no result: {shown}")
    check(any(r.startswith("Made ") for r in shown), "no 'Made ...' report")
    jargon = [r for r in shown if JARGON.search(r)]
    check(not jargon, f"messages a user cannot act on: {jargon}")
    unexplained = [r for r in shown if not r.startswith("Made ")
                   and not re.search(r"(?i)\b(set|raise|lower|try|select|install)\b", r)]
    check(not unexplained, f"messages that do not say what to do: {unexplained}")
    yield 1.0
    shot("ui_real_scan.png")
    log("UI CHECK OK")
    finish(0)


_flow = flow()
bpy.app.timers.register(guarded(lambda: next(_flow)), first_interval=2.0)
