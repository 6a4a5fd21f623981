"""Distance fields kept on disk between benchmark runs (``python -m lab bench --fields DIR``).

A benchmark shape's field (the network's band of distances, :func:`engine.field.compute_udf_band`)
costs about as much as meshing it. A change to the mesher alone leaves every field as it was, so
a run with ``--fields`` saves each shape's field under a key of everything that makes it: the
points in the unit frame, the reconstruction settings, the UDF source and the engine's code and
weights outside ``engine/meshing``. A later run with the same key meshes the saved field instead
of computing it; any change to the field's code or weights gives new keys, so a stale field is
never read. The mesh from a saved field is the mesh from a computed one, bit for bit.
"""

import hashlib
import os
from contextlib import contextmanager
from functools import lru_cache
from pathlib import Path

import numpy as np

ENGINE = Path(__file__).resolve().parents[2] / "engine"


@lru_cache(maxsize=1)
def field_code_hash() -> str:
    """A digest of the engine's Python files and weights, its mesher (``engine/meshing``) left
    out: the code and data a field depends on."""
    digest = hashlib.sha256()
    for path in sorted(ENGINE.rglob("*")):
        relative = path.relative_to(ENGINE)
        if not path.is_file() or relative.parts[0] == "meshing" or "__pycache__" in relative.parts:
            continue
        if path.suffix != ".py" and relative.parts[0] != "weights":
            continue
        digest.update(str(relative).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def field_key(points_unit: np.ndarray, settings, udf_source: str) -> str:
    """The file name (no folder) of the field these points and settings give."""
    digest = hashlib.sha256(field_code_hash().encode())
    points = np.ascontiguousarray(points_unit, dtype=np.float64)
    digest.update(repr(points.shape).encode())
    digest.update(points.tobytes())
    digest.update(repr(settings).encode())
    digest.update(udf_source.encode())
    return digest.hexdigest()[:32] + ".npz"


def save_field(path: Path, band) -> None:
    """Write a :class:`engine.field.BandField` (its grid's band, frame and stats) atomically."""
    import json

    grid = band.grid
    indices, values = grid.band()
    flat = np.ravel_multi_index(indices.T, grid.shape)
    temporary = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(temporary, "wb") as file:
        np.savez_compressed(file, flat=flat, values=values, shape=np.asarray(grid.shape),
                            origin=np.asarray(grid.origin, np.float64),
                            spacing=np.float64(grid.spacing),
                            far_value=np.float64(grid.far_value),
                            stats=np.asarray(json.dumps(band.stats)))
    os.replace(temporary, path)


def load_field(path: Path):
    """The :class:`engine.field.BandField` :func:`save_field` wrote; its stats say
    ``from_cache``."""
    import json

    from engine.field import BandField
    from engine.udf_grid import UDFGrid

    with np.load(path) as saved:
        shape = tuple(int(n) for n in saved["shape"])
        indices = np.stack(np.unravel_index(saved["flat"], shape), axis=1)
        grid = UDFGrid.from_band(indices, saved["values"], shape, saved["origin"],
                                 float(saved["spacing"]), far_value=float(saved["far_value"]))
        stats = json.loads(str(saved["stats"]))
    stats["from_cache"] = True
    return BandField(grid, stats)


@contextmanager
def kept_fields(folder):
    """Within the block, :func:`engine.reconstruct.reconstruct` reads each field from ``folder``
    when it is there and writes it there when it is not."""
    import engine.reconstruct as reconstruct_module

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    compute = reconstruct_module.compute_udf_band

    def compute_or_load(points_unit, settings, progress=None, cancel=None,
                        udf_source="network", **more):
        path = folder / field_key(points_unit, settings, udf_source)
        if path.exists():
            return load_field(path)
        band = compute(points_unit, settings, progress, cancel, udf_source=udf_source, **more)
        save_field(path, band)
        return band

    reconstruct_module.compute_udf_band = compute_or_load
    try:
        yield
    finally:
        reconstruct_module.compute_udf_band = compute
