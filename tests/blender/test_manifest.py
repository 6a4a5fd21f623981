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
            "/lab/"} <= set(excluded)
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
    assert {"blender_manifest.toml", "__init__.py", "LICENSE", "runtime/bridge.py",
            "engine/reconstruct.py", "scripts/batch_reconstruct.py"} <= set(names)
    assert not [n for n in names if n.startswith(("tests/", "docs/", "tools/", ".",
                                                  "lab/", "bench_results/",
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


# --- zips per platform and Python version (wheels faked: no network) ------------------------------

def _fake_wheel(folder, filename: str, numpy_spec: str = "") -> Path:
    name, version = filename.split("-")[:2]
    path = folder / filename
    with zipfile.ZipFile(path, "w") as archive:
        requires = f"Requires-Dist: numpy{numpy_spec}\n" if numpy_spec else ""
        archive.writestr(f"{name}-{version}.dist-info/METADATA",
                         f"Metadata-Version: 2.1\nName: {name}\nVersion: {version}\n{requires}")
    return path


_PLATFORM_TAG = {"linux-x64": "manylinux_2_17_x86_64", "windows-x64": "win_amd64"}


def _fake_download(platform, python_version, folder, numpy_spec=">=1.23.5"):
    """What pip would download: the scipy pin of requirements.txt for this Python as a binary
    wheel of the platform, a pure-Python wheel, and numpy (which the build must drop)."""
    tool = _load_build_tool()
    (scipy,) = [r for r in tool.bundled_requirements(python_version, platform)
                if r.startswith("scipy")]
    abi = "cp" + python_version.replace(".", "")
    tag = _PLATFORM_TAG[platform]
    return [_fake_wheel(folder, f"scipy-{scipy.split('==')[1]}-{abi}-{abi}-{tag}.whl",
                        numpy_spec),
            _fake_wheel(folder, "threadpoolctl-3.5.0-py3-none-any.whl"),
            _fake_wheel(folder, f"numpy-2.2.4-{abi}-{abi}-{tag}.whl")]


def _manifest(zip_path) -> dict:
    return tomllib.loads(zipfile.ZipFile(zip_path).read("blender_manifest.toml").decode())


def test_one_command_builds_a_zip_per_platform_and_python_and_a_lean_one(tmp_path, monkeypatch):
    tool = _load_build_tool()
    monkeypatch.setattr(tool, "PLATFORM_TAGS", {p: tool.PLATFORM_TAGS[p] for p in _PLATFORM_TAG})
    monkeypatch.setattr(tool, "download_wheels", _fake_download)
    assert tool.main(["--output-dir", str(tmp_path)]) == 0

    zips = sorted(p.name for p in tmp_path.glob("*.zip"))
    assert zips == [f"{EXTENSION_ID}-0.1.0-{platform}-python{python}.zip"
                    for platform in ("linux_x64", "windows_x64")
                    for python in ("3.11", "3.13")] + [f"{EXTENSION_ID}-0.1.0.zip"]
    for name in zips:
        zip_path = tmp_path / name
        assert _extension_cli(["validate", str(zip_path)]) == 0, name
        manifest = _manifest(zip_path)
        # No Blender version bounds: Blender refuses a zip for another Python by its wheels.
        assert manifest["blender_version_min"] == "4.2.0" and "blender_version_max" not in manifest
        wheels = [n for n in zipfile.ZipFile(zip_path).namelist() if n.startswith("wheels/")]
        if name == f"{EXTENSION_ID}-0.1.0.zip":
            assert not wheels and "wheels" not in manifest
            continue
        platform, python = name[:-4].split("-")[2:]
        abi = "cp" + python.removeprefix("python").replace(".", "")
        scipy = "1.13.1" if abi == "cp311" else "1.15.3"
        tag = _PLATFORM_TAG[platform.replace("_", "-")]
        assert sorted(wheels) == [f"wheels/scipy-{scipy}-{abi}-{abi}-{tag}.whl",
                                  "wheels/threadpoolctl-3.5.0-py3-none-any.whl"], name
        assert manifest["build"]["generated"]["platforms"] == [platform.replace("_", "-")]


def test_wheels_that_refuse_blenders_numpy_stop_the_build(tmp_path, monkeypatch):
    tool = _load_build_tool()
    monkeypatch.setattr(tool, "download_wheels",
                        lambda *args: _fake_download(*args, numpy_spec="<2"))
    with pytest.raises(SystemExit, match=r"(?s)Blender's numpy.*scipy-1\.15\.3-cp313.*"
                                         r"needs numpy<2, Blender with Python 3\.13 ships"):
        tool.main(["--platform", "linux-x64", "--python-version", "3.13",
                   "--output-dir", str(tmp_path)])
    assert not list(tmp_path.glob("*.zip"))


def test_requirements_are_chosen_per_python_and_platform():
    tool = _load_build_tool()
    for python in tool.PYTHON_VERSIONS:
        for platform in tool.PLATFORM_TAGS:
            requirements = tool.bundled_requirements(python, platform)
            names = [tool._normal(r.split("[")[0].split("=")[0]) for r in requirements]
            assert "numpy" not in names and "torch" not in names
            assert {"scipy", "scikit-image", "laspy"} <= set(names)
            # the mesher's compiled passes; numba has no wheels for Intel Macs
            assert ("numba" in names) == (platform != "macos-x64")
            assert all("==" in r and ";" not in r for r in requirements)
    assert "scipy==1.13.1" in tool.bundled_requirements("3.11", "linux-x64")
    assert "scipy==1.15.3" in tool.bundled_requirements("3.13", "linux-x64")
