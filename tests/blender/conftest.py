"""Fixtures for the Blender tests: the same suite runs with the bpy module and in a real Blender.

The extension is enabled the way users get it: a throw-away extension repository whose only
entry is a symlink named after the manifest id pointing at this checkout (the checkout itself may
be called anything, e.g. ``project`` in CI), so the package is ``bl_ext.udfr_tests.
udf_reconstruction`` and every import inside it must be relative, exactly as in production.
"""

import importlib
import os
import sys
import tempfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
EXTENSION_ID = "udf_reconstruction"
REPO_MODULE = "udfr_tests"
PACKAGE = f"bl_ext.{REPO_MODULE}.{EXTENSION_ID}"

if "bpy" not in sys.modules:
    # bpy module: keep the user's Blender configuration out of the tests. (A real Blender reads
    # BLENDER_USER_RESOURCES at startup; `make test-blender` sets it.)
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="udfr_user_"))

bpy = pytest.importorskip("bpy")
import addon_utils  # noqa: E402  (needs bpy first)


class Extension:
    """The extension under test, enabled through a throw-away extension repository."""

    id = EXTENSION_ID
    package = PACKAGE
    root = ROOT

    def enable(self):
        """Enable the extension; return its package module."""
        prefs = bpy.context.preferences
        if REPO_MODULE not in {repo.module for repo in prefs.extensions.repos}:
            parent = Path(tempfile.mkdtemp(prefix="udfr_repo_"))
            (parent / EXTENSION_ID).symlink_to(ROOT, target_is_directory=True)
            prefs.extensions.repos.new(name="UDF tests", module=REPO_MODULE,
                                       custom_directory=str(parent), source='USER')
            addon_utils.extensions_refresh(ensure_wheels=False)
        errors = []
        module = addon_utils.enable(PACKAGE, default_set=True, handle_error=errors.append)
        if module is None:
            raise RuntimeError(f"enabling {PACKAGE} failed: {errors}")
        return module

    def disable(self) -> None:
        addon_utils.disable(PACKAGE, default_set=True)

    def module(self, name: str):
        """A submodule of the extension, e.g. ``module("runtime.bridge")``."""
        return importlib.import_module(f"{PACKAGE}.{name}")


@pytest.fixture(scope="session")
def extension():
    """The enabled extension (see :class:`Extension`)."""
    handle = Extension()
    handle.enable()
    return handle


@pytest.fixture
def scene(extension):
    """An empty scene (the extension stays enabled); returns ``bpy.context.scene``."""
    bpy.ops.wm.read_homefile(use_empty=True)
    assert PACKAGE in bpy.context.preferences.addons, "reading the home file disabled us"
    return bpy.context.scene
