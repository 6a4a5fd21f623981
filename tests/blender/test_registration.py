"""Enabling and disabling the extension, as Blender does it."""

import sys
import time

import bpy



def test_enable_disable_twice_leaves_nothing_behind(extension):
    for _ in range(2):
        extension.disable()
        assert not hasattr(bpy.types.Scene, "udf_reconstruction")
        assert not hasattr(bpy.types, "UDFR_PT_reconstruct")
        assert not hasattr(bpy.types, "UDF_RECONSTRUCTION_OT_reconstruct")
        started = time.perf_counter()
        extension.enable()
        assert time.perf_counter() - started < 1.0, "enabling must stay fast"
        assert hasattr(bpy.types.Scene, "udf_reconstruction")
        assert hasattr(bpy.types, "UDFR_PT_reconstruct")
        assert hasattr(bpy.types, "UDFR_PT_advanced")
        assert hasattr(bpy.types, "UDF_RECONSTRUCTION_OT_reconstruct")
    assert extension.package in bpy.context.preferences.addons


def test_enabling_does_not_import_the_engine_pipeline(extension):
    package = extension.package
    extension.disable()
    for name in [n for n in sys.modules if n.startswith(package)]:
        del sys.modules[name]
    extension.enable()
    loaded = {n for n in sys.modules if n.startswith(package)}
    assert f"{package}.engine.reconstruct" not in loaded
    assert f"{package}.engine.settings" in loaded  # the panel's defaults come from it


def test_settings_live_on_the_scene_and_survive_save_and_load(scene, tmp_path):
    props = scene.udf_reconstruction
    props.radius_mode = 'fixed'
    props.radius = 0.025
    props.resolution = 96
    props.seed = 7
    path = str(tmp_path / "settings.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.read_homefile(use_empty=True)
    assert bpy.context.scene.udf_reconstruction.resolution == 256
    bpy.ops.wm.open_mainfile(filepath=path)
    props = bpy.context.scene.udf_reconstruction
    assert (props.radius_mode, props.resolution, props.seed) == ('fixed', 96, 7)
    assert abs(props.radius - 0.025) < 1e-6


def test_dragging_one_end_of_the_range_pushes_the_other(scene):
    props = scene.udf_reconstruction
    props.rho_min, props.rho_max = 0.5, 0.8
    props.rho_min = 0.9
    assert props.rho_max == props.rho_min
    props.rho_max = 0.3
    assert props.rho_min == props.rho_max


def test_panel_settings_become_the_engine_settings(scene, extension):
    properties = extension.module("ui.properties")
    settings_module = extension.module("engine.settings")
    assert properties.to_settings(scene.udf_reconstruction) == \
        settings_module.ReconstructSettings(), "panel defaults are the engine's defaults"
    scene.udf_reconstruction.resolution = 80
    scene.udf_reconstruction.outliers = "keep"
    scene.udf_reconstruction.outlier_ratio = 3.0
    settings = properties.to_settings(scene.udf_reconstruction)
    assert (settings.resolution, settings.outliers, settings.outlier_ratio) == (80, "keep", 3.0)


def test_preferences_list_the_dependencies(extension):
    preferences = extension.module("ui.preferences")
    dependencies = extension.module("runtime.dependencies")
    rows = {name: version for name, version, _, _ in preferences.dependency_status()}
    assert rows["numpy"] is not None
    assert set(rows) >= {"scipy", "scikit-image"}
    # One table: the preferences list exactly what the Reconstruct button checks.
    assert list(rows) == [distribution for _, distribution, _, _ in dependencies.DEPENDENCIES]


def _imported_packages(folder) -> set:
    """The extension's top-level packages that the modules of ``folder`` import (relative
    imports: ``from ..runtime import job`` -> runtime)."""
    import ast
    from pathlib import Path

    found = set()
    for path in (Path(__file__).resolve().parents[2] / folder).glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level == 2:
                found.add((node.module or "").split(".")[0] or "extension root")
    return found


def test_the_panel_and_the_operators_do_not_import_each_other():
    assert "operators" not in _imported_packages("ui")
    assert "ui" not in _imported_packages("operators")
    assert not {"ui", "operators"} & _imported_packages("runtime")
