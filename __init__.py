"""UDF Reconstruction: turn point clouds into meshes (Blender extension entry point).

Only registration lives here, and importing this file imports nothing: bpy, the operators and
the panel are imported when Blender calls :func:`register`. So the package imports without
Blender (pytest collects this file as the package of every test, and the engine suite runs in a
venv without bpy), and the engine (``engine/``, no bpy) is imported only when a reconstruction
starts, never while the extension is enabled.

Registration comes in two parts. The preferences and their Install Missing Packages button need
nothing but Blender, so they always register. The panel and the operators need numpy, which some
Linux distributions' Blenders lack: they register once numpy can be imported, at enable time or
right after the button installed it (:func:`register_main`), without a restart.
"""

import importlib.util

_main = {"registered": False}


def _always():
    """The modules that need only Blender: the preferences and the install button."""
    from .operators import install
    from .ui import preferences

    return preferences, install


def _main_modules():
    """The modules that need numpy, in order: properties first (the panel and operators read
    them), panels last."""
    from .operators import reconstruct
    from .ui import panel, properties

    return properties, reconstruct, panel


def register_main() -> bool:
    """Register the panel and the operators when numpy can be imported; True when they are."""
    if _main["registered"] or importlib.util.find_spec("numpy") is None:
        return _main["registered"]
    import bpy

    modules = _main_modules()
    for module in modules:
        for cls in module.CLASSES:
            bpy.utils.register_class(cls)
    bpy.types.Scene.udf_reconstruction = bpy.props.PointerProperty(
        type=modules[0].UDFR_SceneSettings)
    _main["registered"] = True
    return True


def register():
    import bpy

    from .runtime import installer

    installer.add_to_path()  # packages installed from the preferences, if any
    for module in _always():
        for cls in module.CLASSES:
            bpy.utils.register_class(cls)
    register_main()


def unregister():
    import bpy

    from .runtime import installer

    if _main["registered"]:
        del bpy.types.Scene.udf_reconstruction
        for module in reversed(_main_modules()):
            for cls in reversed(module.CLASSES):
                bpy.utils.unregister_class(cls)
        _main["registered"] = False
    for module in reversed(_always()):
        for cls in reversed(module.CLASSES):
            bpy.utils.unregister_class(cls)
    installer.remove_from_path()
