"""UDF Reconstruction: turn point clouds into meshes (Blender extension entry point).

Only registration lives here. The engine (``engine/``, no bpy) is imported when a reconstruction
starts, never while the extension is enabled, so enabling stays fast.
"""

import bpy

from .operators import reconstruct
from .ui import panel, preferences, properties

# Properties first (the panel and operators read them), panels last.
_MODULES = (preferences, properties, reconstruct, panel)


def register():
    for module in _MODULES:
        for cls in module.CLASSES:
            bpy.utils.register_class(cls)
    bpy.types.Scene.udf_reconstruction = bpy.props.PointerProperty(
        type=properties.UDFR_SceneSettings)


def unregister():
    del bpy.types.Scene.udf_reconstruction
    for module in reversed(_MODULES):
        for cls in reversed(module.CLASSES):
            bpy.utils.unregister_class(cls)
