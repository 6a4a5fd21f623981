"""The engine and its tests never need Blender: with ``import bpy`` made to fail, every engine
module and the extension's root package (which pytest collects as the package of every test)
still import, importing the reconstruction pipeline loads neither bpy nor torch, and no engine
module imports the unshipped ``lab`` package."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

_NO_BPY = """
import importlib, importlib.util, pkgutil, sys
sys.modules["bpy"] = None  # any `import bpy` now raises ImportError
sys.path.insert(0, ".")
import engine.reconstruct
assert "torch" not in sys.modules, "importing the pipeline loaded torch"
for info in pkgutil.walk_packages(engine.__path__, "engine."):
    importlib.import_module(info.name)
assert not [m for m in sys.modules if m.split(".")[0] == "lab"], "the engine imports lab"
spec = importlib.util.spec_from_file_location("udf_reconstruction", "__init__.py",
                                              submodule_search_locations=["."])
root = importlib.util.module_from_spec(spec)
sys.modules["udf_reconstruction"] = root
spec.loader.exec_module(root)
assert callable(root.register) and callable(root.unregister)
print("ok")
"""


def test_engine_and_extension_root_import_without_bpy():
    out = subprocess.run([sys.executable, "-c", _NO_BPY], cwd=ROOT, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().endswith("ok")
