"""The panel's properties are generated from ReconstructSettings' fields: every field is there
with its label, default, range and choices; a new field appears with no edit; the Reconstruct
operator reads them back into the engine's settings."""

from dataclasses import dataclass, fields

import bpy

from tests.blender.helpers import add_cloud, sphere_points


def test_every_setting_is_a_panel_property_with_its_label_default_and_range(scene, extension):
    settings = extension.module("engine.settings")
    rna = scene.udf_reconstruction.bl_rna.properties
    for item in fields(settings.ReconstructSettings):
        info = settings.setting_info(item)
        prop = rna[item.name]
        assert (prop.name, prop.description) == (info.label, info.description), item.name
        if info.choices:
            assert [i.identifier for i in prop.enum_items] == list(info.values)
            assert prop.default == item.default
        elif isinstance(item.default, str):
            assert prop.default == item.default, item.name
        else:
            assert abs(prop.default - item.default) < 1e-6, item.name
        if info.low is not None:
            assert abs(prop.hard_min - info.low) < 1e-6, item.name
        if info.high is not None:
            assert abs(prop.hard_max - min(info.high, 2 ** 31 - 1)) < 1e-6, item.name
    assert scene.udf_reconstruction.udf_source == "network"
    assert rna["hide_source"].default is True, "the panel's own property is kept"


def test_a_new_setting_appears_in_the_generated_properties(scene, extension):
    settings = extension.module("engine.settings")
    properties = extension.module("ui.properties")

    @dataclass
    class WithNewSettings(settings.ReconstructSettings):
        smoothing: float = settings.setting(0.5, "Smoothing", "How much the mesh is smoothed",
                                            low=0.0, high=1.0, precision=2)
        passes: int = settings.setting(3, "Passes", "Smoothing passes", low=1, high=10)
        fill: str = settings.setting(
            "holes", "Fill", "What to fill",
            choices=(settings.Choice("holes", "Holes", "Small holes"),
                     settings.Choice("nothing", "Nothing", "Leave every hole open")))
        keep_colours: bool = settings.setting(True, "Keep Colours", "Carry the colours over")
        rounds: int = 2  # declared without setting(): still a property, named after the field

    group = properties.property_group(WithNewSettings, "UDFR_TestSettings", "A test group.")
    bpy.utils.register_class(group)
    bpy.types.Scene.udfr_test = bpy.props.PointerProperty(type=group)
    try:
        props = scene.udfr_test
        rna = props.bl_rna.properties
        assert (rna["smoothing"].name, rna["smoothing"].hard_max, rna["smoothing"].precision) \
            == ("Smoothing", 1.0, 2)
        assert (rna["passes"].hard_min, rna["passes"].hard_max) == (1, 10)
        assert [i.identifier for i in rna["fill"].enum_items] == ["holes", "nothing"]
        assert (rna["rounds"].name, rna["rounds"].default) == ("Rounds", 2)
        assert properties.to_settings(props, WithNewSettings) == WithNewSettings()
        props.smoothing, props.passes, props.fill, props.keep_colours = 0.3, 5, "nothing", False
        props.resolution, props.rounds = 96, 3
        assert properties.to_settings(props, WithNewSettings) == WithNewSettings(
            smoothing=0.3, passes=5, fill="nothing", keep_colours=False, rounds=3,
            resolution=96)
        props.passes = 50
        assert props.passes == 10, "Blender clamps to the setting's range"
    finally:
        del bpy.types.Scene.udfr_test
        bpy.utils.unregister_class(group)


def test_the_operator_reads_every_panel_value_into_the_engine_settings(scene, extension):
    settings = extension.module("engine.settings")
    runtime_job = extension.module("runtime.job")
    props = scene.udf_reconstruction
    props.radius, props.rho_min, props.outlier_ratio = 0.021, 0.55, 3.3
    props.udf_source, props.radius_mode, props.seed = "nearest", "learned", 12
    add_cloud("Scan", sphere_points(2000, 1.0))
    job = runtime_job.start_job(bpy.context)
    try:
        assert job.settings == settings.ReconstructSettings(
            radius=0.021, rho_min=0.55, outlier_ratio=3.3, udf_source="nearest",
            radius_mode="learned", seed=12), "single-precision floats arrive as typed"
    finally:
        runtime_job.end_job()  # the job was never started
