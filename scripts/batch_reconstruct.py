"""Reconstruct point-cloud files without the user interface.

    blender -b --factory-startup --python-exit-code 1 --python scripts/batch_reconstruct.py -- \\
        scans/*.ply more_scans/ --output meshes/ --resolution 192 --blend meshes/all.blend \\
        --preview meshes/preview.png
    .venv/bin/python scripts/batch_reconstruct.py scans/ --output meshes/      # the bpy module

Each input file (folders are searched for readable files, not recursively) is reconstructed with
the same settings the N-panel uses: the open .blend file's panel values (the defaults otherwise),
overridden by the options given here. Meshes are written as ``OUTPUT/<name>.ply`` (``--format``
picks OBJ or OFF), optionally also gathered into a .blend file and rendered into a PNG preview
(Workbench, which works in background mode). Progress goes to stdout; the exit status is 0 when
every input worked, 1 when some failed, 2 for bad options. A failing input (unreadable, corrupt,
no surface found, even an unexpected error) is reported with its reason and the batch goes on
to the next; the run ends with a summary that lists every failure.

Before any work the outputs are checked: a mesh that would be written over one of the inputs
(``--output`` the inputs' own folder with their format), two inputs that would share a mesh, an
unwritable folder or a ``--device cuda`` without a GPU stop the run with status 2 and nothing
touched. Meshes are written atomically; an empty result is a failure and writes nothing.

Without Blender's ``bpy`` module (a plain Python with the engine's dependencies) the script
still reconstructs, with the engine's default settings and the options given here; only
``--blend`` and ``--preview`` need Blender.

The extension is found in this order: an enabled extension (``--addons bl_ext.<repo>.
udf_reconstruction``); an installed but disabled one (enabled for the run); else the folder this
script lives in (a checkout or an installed copy), imported as the package ``udf_reconstruction``
straight from its ``__init__.py``, so the checkout's folder name does not matter and ``sys.path``
is left alone.
"""

import argparse
import importlib
import importlib.util
import re
import signal
import sys
import threading
import time
import types
from pathlib import Path

import numpy as np

try:
    import bpy
except ImportError:  # a plain Python: the engine alone (no .blend, no preview)
    bpy = None

EXTENSION_ID = "udf_reconstruction"


def load_extension():
    """The extension's package module, registered."""
    suffix = "." + EXTENSION_ID
    for name, module in list(sys.modules.items()):
        if name.startswith("bl_ext.") and name.endswith(suffix):
            return module
    import addon_utils
    for module in addon_utils.modules():
        if module.__name__.startswith("bl_ext.") and module.__name__.endswith(suffix):
            return addon_utils.enable(module.__name__, default_set=False)
    root = Path(__file__).resolve().parents[1]
    spec = importlib.util.spec_from_file_location(
        EXTENSION_ID, root / "__init__.py", submodule_search_locations=[str(root)])
    module = importlib.util.module_from_spec(spec)
    sys.modules[EXTENSION_ID] = module
    spec.loader.exec_module(module)
    module.register()
    return module


def load_engine_only():
    """The package of this checkout without its Blender half: a package module whose
    ``__init__.py`` (which imports bpy) is not run, so ``<package>.engine`` imports alone."""
    root = Path(__file__).resolve().parents[1]
    module = sys.modules.get(EXTENSION_ID)
    if module is None:
        module = types.ModuleType(EXTENSION_ID, "UDF Reconstruction (engine only, no bpy)")
        module.__path__ = [str(root)]
        module.__file__ = str(root / "__init__.py")
        sys.modules[EXTENSION_ID] = module
    return module


def script_arguments() -> list:
    """The arguments meant for this script: after ``--`` inside Blender, all of them otherwise."""
    if "--" in sys.argv:
        return sys.argv[sys.argv.index("--") + 1:]
    if bpy is not None and bpy.app.binary_path:
        return []  # a real Blender without "--": no arguments for us
    return sys.argv[1:]  # the bpy module (no binary) or a plain Python


def build_parser(add_settings_arguments, read_formats, write_formats):
    parser = argparse.ArgumentParser(
        prog="batch_reconstruct.py",
        description="Reconstruct meshes from point-cloud files with UDF Reconstruction.")
    parser.add_argument("inputs", nargs="+", metavar="INPUT",
                        help=f"point-cloud files or folders of them "
                             f"({', '.join(f.lower() for f in read_formats)})")
    parser.add_argument("--output", "-o", required=True, metavar="DIR",
                        help="folder for the meshes (created when missing)")
    parser.add_argument("--format", default="ply", choices=[f.lower() for f in write_formats],
                        help="mesh file format (default: ply)")
    parser.add_argument("--blend", metavar="FILE", help="also save all meshes in this .blend")
    parser.add_argument("--preview", metavar="PNG",
                        help="also render the meshes into this PNG (one file per input, "
                             "suffixed with its name, when there are several)")
    group = parser.add_argument_group(
        "reconstruction settings (default: the open file's panel values, else the panel's "
        "defaults; lengths are fractions of each cloud's longest side)")
    add_settings_arguments(group, use_defaults=False)
    return parser


def input_files(inputs, read_formats) -> list:
    """The files to reconstruct: files as given, folders expanded to their readable files."""
    extensions = {"." + f.lower() for f in read_formats}
    files = []
    for item in map(Path, inputs):
        if item.is_dir():
            files += sorted(p for p in item.iterdir() if p.suffix.lower() in extensions)
        else:
            files.append(item)
    return files


class ProgressPrinter:
    """Prints a job's progress when it has moved on 10 % or entered a new stage."""

    def __init__(self, prefix: str):
        self.prefix, self.last_fraction, self.last_message = prefix, -1.0, None

    def __call__(self, fraction: float, message: str) -> None:
        stage = re.sub(r"[\d,./()]+", "", message)  # "optimising (4/200)" is one stage
        if fraction - self.last_fraction >= 0.1 or stage != self.last_message:
            print(f"{self.prefix} {fraction:4.0%} {message}", flush=True)
            self.last_fraction, self.last_message = fraction, stage


def mesh_paths(files, folder: Path, extension: str) -> list:
    """The mesh file of each input: ``folder/<stem>.<extension>``, a ``_`` added to the stem
    while it is taken (the same file name in two folders)."""
    paths, used = [], set()
    for path in files:
        name = path.stem
        while name.lower() in used:
            name += "_"
        used.add(name.lower())
        paths.append(folder / f"{name}.{extension}")
    return paths


def render_preview(context, objects, path: Path) -> None:
    """Render ``objects`` alone with Workbench from a three-quarter view into ``path``."""
    from mathutils import Vector

    scene = context.scene
    hidden = [o for o in scene.objects if o not in objects and not o.hide_render]
    for obj in hidden:
        obj.hide_render = True
    corners = np.array([tuple(o.matrix_world @ Vector(c)) for o in objects for c in o.bound_box])
    low, high = corners.min(axis=0), corners.max(axis=0)
    center, size = Vector((low + high) / 2), float(np.max(high - low))

    camera = bpy.data.objects.new("Preview Camera", bpy.data.cameras.new("Preview Camera"))
    scene.collection.objects.link(camera)
    camera.location = center + Vector((1.0, -1.3, 0.8)).normalized() * size * 2.2
    camera.rotation_euler = (center - camera.location).to_track_quat('-Z', 'Y').to_euler()
    camera.data.clip_end = size * 10
    previous_camera, scene.camera = scene.camera, camera

    scene.render.engine = 'BLENDER_WORKBENCH'
    shading = scene.display.shading
    colored = all(o.data.color_attributes for o in objects)
    shading.color_type = 'VERTEX' if colored else 'SINGLE'
    shading.light = 'STUDIO'
    scene.render.resolution_x, scene.render.resolution_y = 960, 720
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = 'PNG'
    scene.render.filepath = str(path)
    try:
        bpy.ops.render.render(write_still=True)
    finally:
        scene.camera = previous_camera
        bpy.data.objects.remove(camera)
        for obj in hidden:
            obj.hide_render = False


def main() -> int:
    if bpy is not None:
        extension = load_extension()
        print(f"extension: {extension.__name__} ({Path(extension.__file__).parent})", flush=True)
    else:
        extension = load_engine_only()
        print(f"engine only, no bpy: {Path(extension.__file__).parent}", flush=True)
    package = extension.__name__
    engine_io = importlib.import_module(package + ".engine.io")
    errors = importlib.import_module(package + ".engine.errors")
    settings_module = importlib.import_module(package + ".engine.settings")
    preflight = importlib.import_module(package + ".engine.commands.preflight")

    settings_args = importlib.import_module(package + ".engine.commands.settings_args")
    parser = build_parser(settings_args.add_settings_arguments, engine_io.READ_FORMATS,
                          engine_io.WRITE_FORMATS)
    args = parser.parse_args(script_arguments())
    if bpy is None and (args.blend or args.preview):
        parser.error("--blend and --preview need Blender (or the bpy module); run the script "
                     "with blender -b --python, or leave them out")
    files = input_files(args.inputs, engine_io.READ_FORMATS)
    if not files:
        parser.error("no readable point-cloud files in the inputs")
    output = Path(args.output)
    meshes = mesh_paths(files, output, args.format)

    if bpy is not None:
        if not bpy.data.filepath:
            bpy.ops.wm.read_homefile(use_empty=True)  # no file given: start from an empty scene
        properties = importlib.import_module(package + ".ui.properties")
        values = properties.to_settings(properties.scene_settings(bpy.context.scene)).to_dict()
    else:
        values = settings_module.ReconstructSettings().to_dict()
    values.update({k: getattr(args, k) for k in values if getattr(args, k) is not None})
    try:
        settings = settings_module.ReconstructSettings.from_dict(values)
        # Before any work: no mesh over an input, writable outputs, a usable device.
        for mesh_path in meshes:
            for path in files:
                if engine_io.same_file(mesh_path, path):
                    raise errors.InputError(
                        f"the mesh of {path} would be written to {mesh_path}, which is the "
                        f"input {path}: choose another --output folder or --format")
        output.mkdir(parents=True, exist_ok=True)
        extras = [Path(p) for p in (args.blend, args.preview) if p]
        for extra in extras:
            extra.parent.mkdir(parents=True, exist_ok=True)
        preflight.check_outputs(meshes, files)
        for extra, kind in ((args.blend, ".blend"), (args.preview, ".png")):
            if extra:
                check_extra(Path(extra), kind, files + meshes, engine_io, errors)
        preflight.check_device(settings.device)
    except errors.InputError as error:
        parser.error(str(error))
    except OSError as error:
        parser.error(f"cannot create the output folder: {error}")
    print(f"settings: {settings.to_dict()}", flush=True)

    reconstruct_to_file = importlib.import_module(
        package + ".engine.reconstruct_to_file").reconstruct_to_file
    stop = stop_on_interrupt()
    failed = []
    try:
        for index, (path, mesh_path) in enumerate(zip(files, meshes), 1):
            prefix = f"[{index}/{len(files)}] {path.name}:"
            if stop.is_set():
                raise KeyboardInterrupt
            try:
                result = reconstruct_one(path, mesh_path, settings, prefix, engine_io,
                                         reconstruct_to_file, stop.is_set)
            except (errors.InputError, OSError) as error:
                reason = str(error)
            except errors.Cancelled:
                raise KeyboardInterrupt from None
            except Exception as error:  # one input's bug must not stop the others
                reason = f"unexpected {type(error).__name__}: {error}"
            else:
                if args.blend or args.preview:  # a mesh written tile by tile is read back
                    mesh = (result.mesh if result.mesh is not None
                            else engine_io.read_mesh(mesh_path))
                    add_to_scene(mesh, mesh_path.stem, args, len(files), prefix, package)
                continue
            print(f"{prefix} error: {reason}", file=sys.stderr, flush=True)
            failed.append((path, reason))
    except KeyboardInterrupt:
        print("interrupted: the meshes written so far are complete; nothing else was "
              "written", file=sys.stderr, flush=True)
        return 130

    if args.blend:
        bpy.ops.wm.save_as_mainfile(filepath=str(Path(args.blend).resolve()),
                                    check_existing=False)
        print(f"saved {args.blend}", flush=True)
    print(f"done: {len(files) - len(failed)} of {len(files)} reconstructed", flush=True)
    for path, reason in failed:
        print(f"failed: {path}: {reason}", flush=True)
    return 1 if failed else 0


def stop_on_interrupt() -> threading.Event:
    """An event that Ctrl+C (SIGINT) or SIGTERM sets; the engine stops at its next cancel check.
    A second signal ends the run at once. (Inside Blender this replaces Blender's own SIGINT
    handler, which would only flag the signal for a render and leave the script running.)"""
    stop = threading.Event()

    def interrupt(signum, frame):
        stop.set()
        signal.signal(signum, signal.default_int_handler if signum == signal.SIGINT
                      else signal.SIG_DFL)

    signal.signal(signal.SIGINT, interrupt)
    signal.signal(signal.SIGTERM, interrupt)
    return stop


def reconstruct_one(path, mesh_path, settings, prefix, engine_io, reconstruct_to_file,
                    cancel):
    """Read one input, reconstruct it into its mesh file (atomically; a tiled mesh written
    tile by tile); return the result. ``cancel()`` true stops it (Cancelled) before the mesh
    file is complete, leaving nothing written."""
    cloud = engine_io.read_point_cloud(path)
    print(f"{prefix} {len(cloud):,} points", flush=True)
    started = time.perf_counter()
    result = reconstruct_to_file(cloud, mesh_path, settings, progress=ProgressPrinter(prefix),
                                 cancel=cancel)
    for message in result.messages:
        print(f"{prefix} note: {message}", flush=True)
    print(f"{prefix} wrote {mesh_path} ({result.stats['faces']:,} faces, "
          f"{time.perf_counter() - started:.1f} s)", flush=True)
    return result


def check_extra(path: Path, extension: str, taken, engine_io, errors) -> None:
    """The .blend or preview file: the right extension, none of the inputs or meshes."""
    if path.suffix.lower() != extension:
        raise errors.InputError(f"{path} must end in {extension}")
    for other in taken:
        if engine_io.same_file(path, other):
            raise errors.InputError(f"{path} would be written over {other}")


def add_to_scene(mesh, name, args, count, prefix, package) -> None:
    """Put the mesh in the scene (for --blend) and render its preview (--preview)."""
    from mathutils import Matrix

    bridge = importlib.import_module(package + ".runtime.bridge")
    context = bpy.context
    obj = bridge.new_mesh_object(context, mesh, name, Matrix.Identity(4))
    if args.preview:
        preview = Path(args.preview)
        if count > 1:
            preview = preview.with_name(f"{preview.stem}_{name}{preview.suffix}")
        render_preview(context, [obj], preview)
        print(f"{prefix} rendered {preview}", flush=True)


if __name__ == "__main__":
    sys.exit(main())
