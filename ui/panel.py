"""The N-panel: View3D sidebar, tab "Reconstruct"."""

import bpy

from ..engine.detail import cell_size
from ..engine.settings import radius_range
from ..runtime import bridge, dependencies
from ..runtime.job import running_job
from .properties import DEVICE_ITEMS, scene_settings


def _length(context, fraction: float, extent: float) -> str:
    """``fraction`` of ``extent`` (a length of the active object) in the scene's units."""
    units = context.scene.unit_settings
    return bpy.utils.units.to_string(units.system, 'LENGTH', fraction * extent * units.scale_length,
                                     precision=3)


def _draw_device(layout, props) -> None:
    """Device as buttons; CUDA greyed out when no GPU was found, and said so."""
    gpu = dependencies.gpu_available()
    split = layout.split(factor=0.4, align=True)  # the property-split look: label | buttons
    heading = split.row()
    heading.alignment = 'RIGHT'
    heading.label(text="Device")
    row = split.row(align=True)
    row.use_property_split = False
    for value, name, _ in DEVICE_ITEMS:
        button = row.row(align=True)
        button.enabled = not (value == "cuda" and gpu is False)
        button.prop_enum(props, "device", value, text=name)
    if gpu is False and props.device != "cpu":
        line = layout.row()
        line.alert = props.device == "cuda"
        line.label(text="No GPU found" if line.alert else "No GPU: runs on the CPU",
                   icon='ERROR' if line.alert else 'INFO')


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

        missing = dependencies.missing_packages()
        if missing:
            column = layout.column(align=True)
            column.alert = True
            for name in missing:
                column.label(text=f"Missing package: {name}", icon='ERROR')
            column.label(text="See Preferences > Add-ons")

        target = bridge.reconstruct_target(context)
        if job is not None:
            layout.label(text=f"Reconstructing {job.source_name}", icon='OUTLINER_OB_POINTCLOUD')
        elif target.problem:
            row = layout.row()
            row.alert = obj is not None and context.mode == 'OBJECT' and obj.select_get()
            row.label(text=target.short, icon='ERROR' if row.alert else 'INFO')
        elif target.is_result:
            layout.label(text=f"{obj.name}: made from {target.source.name}", icon='MESH_DATA')
        else:
            layout.label(text=f"{obj.name}: {target.count:,} points",
                         icon='OUTLINER_OB_POINTCLOUD')
        count = target.count
        extent = bridge.world_extent(target.source) if count else 0.0
        # radii are fractions of Resolution cells: the longest side unless the cells are finer
        voxel, cells, capped = cell_size(count, extent, props) if extent else (0.0, 0.0, False)
        scale = voxel * props.resolution

        body = layout.column()
        body.enabled = job is None
        body.prop(props, "radius_mode", expand=True)

        if props.radius_mode == 'fixed':
            body.prop(props, "radius")
            if extent:
                body.label(text=f"Radius {_length(context, props.radius, scale)}")
        else:
            body.prop(props, "custom_range")
            if props.custom_range:
                body.prop(props, "parent_radius")
                column = body.column(align=True)
                column.prop(props, "rho_min", text="Range Min")
                column.prop(props, "rho_max", text="Max")
            if extent:
                parent, rho_min, rho_max = radius_range(props)
                low, high = rho_min * parent, rho_max * parent
                body.label(text=f"Radius {_length(context, low, scale)} "
                                f"to {_length(context, high, scale)}")
        body.prop(props, "detail")
        body.prop(props, "voxel_size" if props.detail == 'voxel_size' else "resolution")
        if extent:
            text = f"Cell {_length(context, voxel, 1.0)} ({cells:,.0f} cells)"
            body.label(text=text + (", auto's finest" if capped else ""))
        _draw_device(body, props)
        body.prop(props, "hide_source")

        if job is None:
            text = "Reconstruct"
            if target.is_result:
                text = "Reconstruct Again"
            layout.operator("udf_reconstruction.reconstruct", text=text, icon='MESH_DATA')
            return
        row = layout.row(align=True)
        text = job.status_text
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
        layout.prop(props, "tile_cells")
        layout.prop(props, "fill_gaps")
        layout.prop(props, "outliers")
        row = layout.row()
        row.enabled = props.outliers != "keep"
        row.prop(props, "outlier_ratio")


CLASSES = (UDFR_PT_reconstruct, UDFR_PT_advanced)
