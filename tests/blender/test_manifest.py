"""The manifest passes Blender's own validator, and the built zip installs and enables."""

import importlib.util
import os
import sys
import tomllib
import zipfile
from pathlib import Path

import addon_utils
import bpy
import pytest

ROOT = Path(__file__).resolve().parents[2]
EXTENSION_ID = "udf_reconstruction"


def _extension_cli(args) -> int:
    from bl_pkg import bl_extension_cli  # Blender's `blender --command extension`, with its tags
    return bl_extension_cli.cli_extension_handler(args)


def test_blenders_validator_accepts_the_manifest(tmp_path):
    # The checkout may be called anything (CI clones into `project`): validate it under its id.
    link = tmp_path / EXTENSION_ID
    link.symlink_to(ROOT, target_is_directory=True)
    assert _extension_cli(["validate", str(link)]) == 0


def test_manifest_fields_follow_the_extension_platform_rules():
    manifest = tomllib.loads((ROOT / "blender_manifest.toml").read_text())
    assert manifest["id"] == EXTENSION_ID
    assert len(manifest["tagline"]) <= 64 and manifest["tagline"][-1].isalnum()
    assert manifest["license"] == ["SPDX:GPL-3.0-or-later"]
    assert manifest["blender_version_min"] == "4.2.0"
    assert "wheels" not in manifest, "tools/build_extension.py adds the wheels per platform"
    excluded = manifest["build"]["paths_exclude_pattern"]
    assert {"__pycache__/", ".*", "/*.zip", "*.blend[1-9]", "/tests/",
            "/engine/training/"} <= set(excluded)
    assert "GNU GENERAL PUBLIC LICENSE" in (ROOT / "LICENSE").read_text()[:200]


def _load_build_tool():
    spec = importlib.util.spec_from_file_location("build_extension",
                                                  ROOT / "tools" / "build_extension.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_built_zip_ships_only_the_extension_and_installs(extension, tmp_path):
    assert _load_build_tool().main(["--no-wheels", "--output-dir", str(tmp_path)]) == 0
    (zip_path,) = tmp_path.glob(f"{EXTENSION_ID}-*.zip")
    names = zipfile.ZipFile(zip_path).namelist()
    assert {"blender_manifest.toml", "__init__.py", "LICENSE", "operators/bridge.py",
            "engine/reconstruct.py", "scripts/batch_reconstruct.py"} <= set(names)
    assert not [n for n in names if n.startswith(("tests/", "docs/", "tools/", ".",
                                                  "engine/training/", "bench_results/",
                                                  "examples/", "benchmarks/"))
                or "__pycache__" in n or "/." in n]

    extension.disable()  # the installed copy registers the same classes
    installed = f"bl_ext.user_default.{EXTENSION_ID}"
    try:
        assert _extension_cli(["install-file", "-r", "user_default", "--no-prefs",
                               str(zip_path)]) == 0
        addon_utils.extensions_refresh()
        assert addon_utils.enable(installed, default_set=True) is not None
        assert hasattr(bpy.types.Scene, "udf_reconstruction")
        assert sys.modules[installed].__file__.startswith(
            os.path.realpath(bpy.utils.user_resource('EXTENSIONS')))
    finally:
        addon_utils.disable(installed, default_set=True)
        _extension_cli(["remove", f"user_default.{EXTENSION_ID}", "--no-prefs"])
        extension.enable()
    assert extension.package in bpy.context.preferences.addons
