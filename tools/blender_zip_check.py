"""Check an installed extension zip inside a real Blender: it enables, finds its packages (after
the Preferences' Install Missing Packages when asked), and reconstructs a generated sphere.

    make check-zip BLENDER=../shared/tools/real-blender/blender \\
        ZIP=dist/udf_reconstruction-0.1.0-linux_x64-python3.13.zip
    make check-zip BLENDER=... ZIP=dist/udf_reconstruction-0.1.0.zip INSTALL_MISSING=1

Run by ``make check-zip`` after ``blender --command extension install-file`` put the zip into a
throw-away user configuration:

    blender -b --python-exit-code 1 --python tools/blender_zip_check.py -- \\
        [--install-missing] [--points 20000] [--resolution 64]

Prints where each package was loaded from, and exits non-zero when a step fails.
"""

import argparse
import importlib
import sys
import time

import addon_utils
import bpy

EXTENSION = "bl_ext.user_default.udf_reconstruction"


def step(text: str) -> None:
    print(f"[zip-check] {text}", flush=True)


def sphere(count: int):
    """A vertex-only mesh object with ``count`` points on a unit sphere, selected and active."""
    import numpy as np  # after the install: this Blender may have come without numpy

    i = np.arange(count) + 0.5
    polar, azimuth = np.arccos(1 - 2 * i / count), np.pi * (1 + 5 ** 0.5) * i
    points = np.c_[np.cos(azimuth) * np.sin(polar), np.sin(azimuth) * np.sin(polar),
                   np.cos(polar)]
    mesh = bpy.data.meshes.new("Sphere")
    mesh.vertices.add(count)
    mesh.vertices.foreach_set("co", points.astype(np.float32).ravel())
    obj = bpy.data.objects.new("Sphere", mesh)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    return obj


def main() -> int:
    parser = argparse.ArgumentParser(prog="blender_zip_check.py")
    parser.add_argument("--install-missing", action="store_true",
                        help="press Install Missing Packages when something is missing")
    parser.add_argument("--points", type=int, default=20_000)
    parser.add_argument("--resolution", type=int, default=64)
    args = parser.parse_args(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else [])
    step(f"Blender {bpy.app.version_string}, Python {sys.version.split()[0]}")

    errors = []
    addon_utils.extensions_refresh(ensure_wheels=True)
    if addon_utils.enable(EXTENSION, default_set=True, handle_error=errors.append) is None:
        step(f"FAILED: the extension does not enable: {errors}")
        return 1
    dependencies = importlib.import_module(EXTENSION + ".runtime.dependencies")
    missing = dependencies.missing_packages()
    step(f"enabled; missing packages: {missing or 'none'}")
    if missing:
        if not args.install_missing:
            step("FAILED: packages are missing")
            return 1
        started = time.perf_counter()
        result = bpy.ops.udf_reconstruction.install_packages()
        installer = importlib.import_module(EXTENSION + ".runtime.installer")
        step(f"Install Missing Packages: {result} in {time.perf_counter() - started:.0f} s: "
             f"{installer.last_result()}")
        if result != {'FINISHED'} or dependencies.missing_packages():
            step("FAILED: the install did not bring the packages")
            return 1
    for module in ("numpy", "scipy", "skimage", "laspy", "trimesh"):
        try:
            loaded = importlib.import_module(module)
            step(f"  {module} {getattr(loaded, '__version__', '?')} from {loaded.__file__}")
        except ImportError as error:
            step(f"  {module}: {error}")

    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.context.scene.udf_reconstruction.resolution = args.resolution
    sphere(args.points)
    started = time.perf_counter()
    result = bpy.ops.udf_reconstruction.reconstruct()
    made = bpy.data.objects.get("Sphere_mesh")
    if result != {'FINISHED'} or made is None or len(made.data.polygons) == 0:
        step(f"FAILED: Reconstruct returned {result}")
        return 1
    import numpy as np

    radii = np.linalg.norm(np.array([v.co for v in made.data.vertices]), axis=1)
    step(f"Reconstruct: {len(made.data.polygons):,} faces from {args.points:,} points at "
         f"{args.resolution} in {time.perf_counter() - started:.1f} s; vertex radius "
         f"{radii.mean():.4f} +- {radii.std():.4f} (true 1)")
    if abs(radii.mean() - 1.0) > 0.01:
        step("FAILED: the mesh is not on the sphere")
        return 1
    step("OK")
    return 0


if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    # os._exit: a windowed Blender would stay open after sys.exit
    import os
    os._exit(code)
