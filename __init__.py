"""UDF Reconstruction: turn point clouds into meshes (Blender extension entry point).

Only registration lives here, and importing this file imports nothing: bpy, the operators and
the panel are imported when Blender calls :func:`register`. So the package imports without
Blender (pytest collects this file as the package of every test, and the engine suite runs in a
venv without bpy), and the engine (``engine/``, no bpy) is imported only when a reconstruction
starts, never while the extension is enabled.
"""


def _modules():
    """The modules whose ``CLASSES`` are registered, in order: properties first (the panel and
    operators read them), panels last."""
    from .operators import install, reconstruct
    from .ui import panel, preferences, properties

    return preferences, properties, install, reconstruct, panel


def register():
    import bpy

    from .operators import install
    from .ui import properties

    install.add_to_path()  # packages installed from the preferences, if any
    for module in _modules():
        for cls in module.CLASSES:
            bpy.utils.register_class(cls)
    bpy.types.Scene.udf_reconstruction = bpy.props.PointerProperty(
        type=properties.UDFR_SceneSettings)


def unregister():
    import bpy

    from .operators import install

    del bpy.types.Scene.udf_reconstruction
    for module in reversed(_modules()):
        for cls in reversed(module.CLASSES):
            bpy.utils.unregister_class(cls)
    install.remove_from_path()
