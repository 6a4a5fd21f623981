"""Helpers shared by the scripts that drive a real, windowed Blender (run with ``--python``):
the largest 3D view and its sidebar, a screenshot of the whole screen, a hard exit."""

import os
import subprocess
import sys

import bpy


def view3d():
    """(window, area, region) of the largest 3D view of the first window."""
    window = bpy.context.window_manager.windows[0]
    area = max((a for a in window.screen.areas if a.type == 'VIEW_3D'),
               key=lambda a: a.width * a.height)
    region = next(r for r in area.regions if r.type == 'WINDOW')
    return window, area, region


def sidebar():
    """The sidebar (N-panel) region of that 3D view."""
    _, area, _ = view3d()
    return next(r for r in area.regions if r.type == 'UI')


def screenshot(path):
    """The X screen as a PNG (``bpy.ops.screen.screenshot`` is black under Xvfb)."""
    subprocess.run(["import", "-window", "root", str(path)], check=True)


def finish(code):
    """Exit Blender now with ``code`` (a timer cannot return an exit status)."""
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
