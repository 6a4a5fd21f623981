"""The optional compiled kernels (numba): loaded ahead of the mesher, or not used at all."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

WARM_UP = """
import threading
from engine.compiled import warm_up
warm_up()
for thread in threading.enumerate():
    if thread.name == "udf-kernels-warm-up":
        thread.join()
from engine import udf_grid_kernels as grid
from engine.meshing import mesh_ops_kernels as ops, optimize_kernels as passes
kernels = (passes.face_rows, passes.vertex_rows, passes.step_rows, ops.edge_topology,
           ops.facing_candidates, grid.bricks)
print(sum(1 for kernel in kernels if kernel.signatures))
"""


def _run(code: str, **env) -> str:
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                          text=True, timeout=600, env={"PATH": "/usr/bin:/bin", **env})
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def test_the_warm_up_loads_every_kernel_in_a_fresh_process():
    """numba is a runtime requirement (requirements.txt): every kernel is ready after it."""
    assert _run(WARM_UP) == "6"


def test_numpy_only_means_no_numba_at_all():
    code = ("import sys; from engine.compiled import warm_up; warm_up(); "
            "from engine.meshing.optimize import compiled_kernels; "
            "print(compiled_kernels() is None, 'numba' in sys.modules)")
    assert _run(code, UDF_RECON_KERNELS="numpy") == "True False"
