"""Helpers shared by the scripts that drive a real, windowed Blender (run with ``--python``):
their arguments, checks, log and screenshots, the largest 3D view and its sidebar, a hard exit."""

import os
import subprocess
import sys
import traceback
from pathlib import Path

import bpy


class Failed(Exception):
    """A check of the flow that did not hold."""


def check(condition, message) -> None:
    """Raise :class:`Failed` with ``message`` unless ``condition`` holds."""
    if not condition:
        raise Failed(message)


_flow = {"tag": "flow", "shots": None}


def start_flow(script: str, tag: str, resolution: int):
    """``(zip, cloud, resolution)`` from the arguments after ``--``, ``ZIP CLOUD.ply SHOT_DIR
    [RES]`` (paths resolved; ``resolution`` when RES is not given); prints the usage and exits 2
    when one is missing. From then on :func:`log` tags its lines ``[tag]`` and :func:`shot`
    writes into SHOT_DIR."""
    args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    if len(args) < 3:
        print(f"usage: blender --python tools/{script} -- ZIP CLOUD.ply SHOT_DIR [RES]")
        finish(2)
    zip_path, cloud, shots = (Path(a).resolve() for a in args[:3])
    _flow.update(tag=tag, shots=shots)
    return zip_path, cloud, int(args[3]) if len(args) > 3 else resolution


def log(message: str) -> None:
    print(f"[{_flow['tag']}] {message}", flush=True)


def shot(name: str) -> None:
    """A screenshot of the whole screen into the flow's shot folder."""
    _flow["shots"].mkdir(parents=True, exist_ok=True)
    screenshot(_flow["shots"] / name)
    log(f"screenshot {_flow['shots'] / name}")


def guarded(step, where=lambda: ""):
    """``step`` as a timer function that, when it raises, logs ``FAILED<where()>: ...`` (with the
    traceback of an unexpected error) and exits 1: a timer that raises is dropped silently and
    Blender would stay open."""
    def tick():
        try:
            return step()
        except Failed as error:
            log(f"FAILED{where()}: {error}")
        except Exception:
            traceback.print_exc()
            log(f"FAILED{where()}: unexpected error")
        finish(1)
    return tick


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
