"""The N-panel: View3D sidebar, tab "Reconstruct"."""

import bpy

from ..operators import bridge
from ..operators.reconstruct import running_job
from .properties import available_radius_modes, scene_settings


def _length(context, fraction: float, extent: float) -> str:
    """A unit-frame length as a real length of the active object, in the scene's units."""
    units = context.scene.unit_settings
    return bpy.utils.units.to_string(units.system, 'LENGTH', fraction * extent * units.scale_length,
                                     precision=3)


class UDFR_PT_reconstruct(bpy.types.Panel):
    bl_idname = "UDFR_PT_reconstruct"
    bl_label = "UDF Reconstruction"
    bl_space_type = 'VIEW_3D'
    bl_region_type = 'UI'
    bl_category = "Reconstruct"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        props = scene_settings(context.scene)
        obj = context.view_layer.objects.active
        job = running_job()

        count = bridge.point_count(context, obj)
        if obj is None:
            layout.label(text="No active object", icon='INFO')
        elif count == 0:
            layout.label(text=f"{obj.name}: no points", icon='ERROR')
        else:
            layout.label(text=f"{obj.name}: {count:,} points", icon='OUTLINER_OB_POINTCLOUD')
        extent = bridge.world_extent(obj) if count else 0.0

        body = layout.column()
        body.enabled = job is None
        body.prop(props, "radius_mode", expand=True)
        available = available_radius_modes()
        if props.radius_mode not in available:
            box = body.box()
            box.label(text=f"'{props.radius_mode}' is not available in this build", icon='ERROR')
            box.label(text=f"Use: {', '.join(sorted(available))}")

        if props.radius_mode == 'fixed':
            body.prop(props, "radius")
            if extent:
                body.label(text=f"Radius {_length(context, props.radius, extent)}")
        else:
            body.prop(props, "parent_radius")
            row = body.row(align=True)
            row.prop(props, "rho_min", text="Range")
            row.prop(props, "rho_max", text="")
            if extent:
                low = props.rho_min * props.parent_radius
                high = props.rho_max * props.parent_radius
                body.label(text=f"Radius {_length(context, low, extent)} "
                                f"to {_length(context, high, extent)}")
        body.prop(props, "resolution")
        if extent:
            body.label(text=f"Cell {_length(context, 1.0 / props.resolution, extent)}")
        body.prop(props, "device")

        if job is None:
            layout.operator("udf_reconstruction.reconstruct", icon='MESH_DATA')
            return
        row = layout.row(align=True)
        text = f"{job.message} ({job.fraction:.0%})"
        if job.stop.is_set():
            text = "Cancelling..."
        if hasattr(row, "progress"):
            row.progress(factor=job.fraction, type='BAR', text=text)
        else:
            row.label(text=text)
        row.operator("udf_reconstruction.cancel", text="", icon='CANCEL')


class UDFR_PT_advanced(bpy.types.Panel):
    bl_idname = "UDFR_PT_advanced"
    bl_label = "Advanced"
    bl_space_type = 'VIEW_3D'
    bl_region_type = 'UI'
    bl_category = "Reconstruct"
    bl_parent_id = "UDFR_PT_reconstruct"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        layout.enabled = running_job() is None
        props = scene_settings(context.scene)
        layout.prop(props, "seed")
        layout.prop(props, "min_component_faces")
        layout.prop(props, "outliers")
        row = layout.row()
        row.enabled = props.outliers != "keep"
        row.prop(props, "outlier_ratio")


CLASSES = (UDFR_PT_reconstruct, UDFR_PT_advanced)
