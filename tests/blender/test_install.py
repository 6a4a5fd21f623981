"""The Preferences button that installs missing packages into the extension's own folder, with a
local wheel folder standing in for PyPI: what it installs, where, that the package imports at
once (no restart), that Blender's numpy is kept, and what a failure says."""

import importlib
import importlib.util
import os
import sys
import zipfile

import bpy
import numpy as np
import pytest

from tests.blender.helpers import Drawn, Host, Layout

PROBE = "udfr_probe"


def make_wheel(folder, name: str, version: str, code: str, requires=()) -> None:
    """A minimal pure-Python wheel of the package ``name`` holding ``code``."""
    distribution = name.replace("_", "-")
    info = f"{name}-{version}.dist-info"
    files = {
        f"{name}/__init__.py": code,
        f"{info}/METADATA": "Metadata-Version: 2.1\nName: {}\nVersion: {}\n{}".format(
            distribution, version, "".join(f"Requires-Dist: {r}\n" for r in requires)),
        f"{info}/WHEEL": "Wheel-Version: 1.0\nGenerator: udfr-tests\nRoot-Is-Purelib: true\n"
                         "Tag: py3-none-any\n",
    }
    files[f"{info}/RECORD"] = "".join(f"{path},,\n" for path in files) + f"{info}/RECORD,,\n"
    with zipfile.ZipFile(folder / f"{name}-{version}-py3-none-any.whl", "w") as archive:
        for path, text in files.items():
            archive.writestr(path, text)


@pytest.fixture
def probe_missing(extension, monkeypatch, tmp_path):
    """A required package ``udfr-probe`` (needing numpy) that is missing, and a local 'index':
    its wheel and a fake numpy wheel of Blender's numpy version. pip sees nothing else."""
    dependencies = extension.module("runtime.dependencies")
    installer = extension.module("runtime.installer")
    monkeypatch.setattr(dependencies, "DEPENDENCIES", dependencies.DEPENDENCIES + (
        (PROBE, "udfr-probe", "testing", True),))
    wheels = tmp_path / "wheels"
    wheels.mkdir()
    monkeypatch.setenv("PIP_NO_INDEX", "1")
    monkeypatch.setenv("PIP_FIND_LINKS", str(wheels))
    monkeypatch.setenv("PIP_CONFIG_FILE", os.devnull)
    folder = installer.packages_folder()
    yield wheels
    installer._state.update(install=None, result=None)
    sys.modules.pop(PROBE, None)
    installer.remove_from_path()
    if os.path.isdir(folder):
        import shutil
        shutil.rmtree(folder)
    importlib.invalidate_caches()


def test_the_button_installs_into_the_extension_folder_and_it_imports_at_once(
        extension, probe_missing):
    dependencies = extension.module("runtime.dependencies")
    installer = extension.module("runtime.installer")
    make_wheel(probe_missing, PROBE, "1.0", "ANSWER = 42\n", requires=["numpy"])
    make_wheel(probe_missing, "numpy", np.__version__, "FAKE = True\n")
    assert dependencies.missing_packages() == ["udfr-probe"]
    assert installer.to_install() == ["udfr-probe"]
    assert bpy.ops.udf_reconstruction.install_packages.poll()

    assert bpy.ops.udf_reconstruction.install_packages() == {'FINISHED'}

    ok, message = installer.last_result()
    assert ok, message
    assert message.startswith("Installed udfr-probe in ") and "no restart needed" in message
    assert dependencies.missing_packages() == []
    probe = importlib.import_module(PROBE)
    assert probe.ANSWER == 42
    folder = installer.packages_folder()
    assert os.path.realpath(probe.__file__).startswith(os.path.realpath(folder))
    assert folder.startswith(bpy.utils.user_resource('EXTENSIONS'))
    # numpy was pulled in as a dependency (at Blender's version) and removed again: only
    # Blender's own numpy can be loaded.
    assert not [name for name in os.listdir(folder) if name.startswith("numpy")]
    assert not hasattr(importlib.import_module("numpy"), "FAKE")
    assert not bpy.ops.udf_reconstruction.install_packages.poll(), "nothing left to install"


def test_the_folder_is_on_the_path_after_enabling_again(extension, probe_missing):
    installer = extension.module("runtime.installer")
    make_wheel(probe_missing, PROBE, "1.0", "ANSWER = 7\n")
    assert bpy.ops.udf_reconstruction.install_packages() == {'FINISHED'}
    extension.disable()
    assert installer.packages_folder() not in sys.path
    extension.enable()
    assert installer.packages_folder() in sys.path
    assert extension.module("runtime.dependencies").is_found(PROBE)


def test_a_failed_install_says_why_and_what_to_do(extension, probe_missing):
    installer = extension.module("runtime.installer")
    path_before = list(sys.path)
    with pytest.raises(RuntimeError) as error:  # no wheel of udfr-probe in the local index
        bpy.ops.udf_reconstruction.install_packages()
    ok, message = installer.last_result()
    assert not ok and str(error.value).strip().endswith(message)
    assert message.startswith("Installing failed: No matching distribution found for "
                              "udfr-probe.")
    assert message.endswith("or install the extension zip made for your Blender.")
    assert extension.module("runtime.dependencies").missing_packages() == ["udfr-probe"]
    assert sys.path == path_before


def test_progress_follows_pips_output(extension):
    installer = extension.module("runtime.installer")
    job = installer.Install(["scipy", "laspy[lazrs]"], "/nowhere", python=sys.executable)
    seen = []
    for line in ["Collecting scipy", "  Downloading scipy-1.15.3-cp313-cp313-manylinux_2_17_"
                 "x86_64.whl (37.3 MB)", "Collecting numpy<2.5,>=1.23.5 (from scipy)",
                 "  Using cached numpy-2.2.4-cp313-cp313-manylinux_2_17_x86_64.whl",
                 "Collecting laspy[lazrs]", "  Downloading laspy-2.5.4-py3-none-any.whl (84 kB)",
                 "Installing collected packages: numpy, scipy, laspy"]:
        job._follow(line)
        seen.append((job.text, round(job.fraction, 3)))
    # 1 of 2 known downloads, 1 of 3 (numpy found), 2 of 3, 2 of 3 (laspy looked up), 3 of 3
    assert seen == [("Looking up scipy", 0.0), ("Downloading scipy (37.3 MB)", 0.425),
                    ("Looking up numpy", 0.425), ("Downloading numpy", 0.567),
                    ("Looking up laspy", 0.567), ("Downloading laspy (84 kB)", 0.85),
                    ("Installing", 0.9)]


def test_the_preferences_offer_the_button_only_when_something_is_missing(
        extension, probe_missing):
    preferences = extension.module("ui.preferences")
    def drawn():
        log = []
        preferences.UDFR_AddonPreferences.draw(Host(Layout(log)), bpy.context)
        return Drawn(log)

    shown = drawn()
    assert ("operator", "udf_reconstruction.install_packages", "", True) in shown.log
    assert "Missing: udfr-probe." in shown.labels
    make_wheel(probe_missing, PROBE, "1.0", "ANSWER = 1\n")
    bpy.ops.udf_reconstruction.install_packages()
    shown = drawn()
    assert not [e for e in shown.log if e[1] == "udf_reconstruction.install_packages"]
    assert any(text.startswith("Installed udfr-probe in ") for text in shown.labels)


def test_without_numpy_the_preferences_come_first_and_the_panel_after_the_install(
        extension, probe_missing, monkeypatch):
    root = importlib.import_module(extension.package)
    find_spec = importlib.util.find_spec
    make_wheel(probe_missing, PROBE, "1.0", "ANSWER = 3\n")
    extension.disable()
    try:
        with monkeypatch.context() as patch:  # a Blender without numpy, as some distributions'
            patch.setattr(root.importlib.util, "find_spec",
                          lambda name, *args: None if name == "numpy" else find_spec(name, *args))
            extension.enable()
            assert hasattr(bpy.ops.udf_reconstruction, "install_packages")
            assert bpy.ops.udf_reconstruction.install_packages.poll()
            assert not hasattr(bpy.types.Scene, "udf_reconstruction")
            assert not hasattr(bpy.types, "UDFR_PT_reconstruct")
        # numpy "arrives" with the install: the panel registers at once, no restart
        assert bpy.ops.udf_reconstruction.install_packages() == {'FINISHED'}
        assert hasattr(bpy.types.Scene, "udf_reconstruction")
        assert hasattr(bpy.types, "UDFR_PT_reconstruct")
    finally:
        extension.disable()
        extension.enable()
    assert hasattr(bpy.types.Scene, "udf_reconstruction")
