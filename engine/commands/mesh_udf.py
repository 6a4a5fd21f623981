"""``python -m engine mesh-udf GRID.npz OUT.ply``: mesh an unsigned distance grid with DCUDF.

GRID.npz holds ``udf`` (float32 (nx, ny, nz), world units), ``origin`` (3 floats, the world
position of ``udf[0, 0, 0]``) and ``spacing`` (one float). Prints the stages, the pieces and any
warnings on stderr; writes the mesh (PLY, OBJ, OFF or STL by extension).
"""

import sys

import numpy as np

from ..errors import InputError
from ..io import WRITE_FORMATS
from ..settings import DEVICES


def add_arguments(parser) -> None:
    """Register the command's arguments on an ``argparse`` parser."""
    parser.add_argument("grid", help="UDF grid (.npz with udf, origin, spacing)")
    parser.add_argument("output", help="output mesh ("
                        + ", ".join(f".{f.lower()}" for f in WRITE_FORMATS) + "); never the grid")
    parser.add_argument("--iso", default=None,
                        help="marching-cubes level: '1.0h' in voxels, or an absolute distance "
                             "(default: automatic, about 1 voxel)")
    parser.add_argument("--iterations", type=int, default=None,
                        help="optimisation iterations (default: the mesher's)")
    parser.add_argument("--no-cut", action="store_true",
                        help="keep both layers of the double cover")
    parser.add_argument("--min-component-faces", type=int, default=0,
                        help="drop output pieces with fewer faces (default 0: keep all)")
    parser.add_argument("--device", default="auto", choices=DEVICES,
                        help="where the optimisation runs: auto (a CUDA GPU when PyTorch sees "
                             "one, else numpy on the CPU), cpu or cuda (default auto)")


def load_grid(path: str):
    """Read GRID.npz into a :class:`~engine.meshing.UDFGrid`; InputError when it is malformed."""
    from ..io import read_npz_arrays
    from ..meshing import UDFGrid

    data, names = read_npz_arrays(path, ("udf", "origin", "spacing"))
    missing = [key for key in ("udf", "origin", "spacing") if key not in data]
    if missing:
        raise InputError(f"{path} lacks {', '.join(missing)} (needs udf, origin, spacing; it "
                         f"has {', '.join(names) or 'nothing'})")
    udf, origin, spacing = data["udf"], data["origin"], data["spacing"]
    if udf.ndim != 3 or not np.issubdtype(udf.dtype, np.number):
        raise InputError(f"udf must be a 3-D numeric array, got shape {udf.shape} "
                         f"of {udf.dtype}")
    if np.shape(origin) not in ((3,), (1, 3)):
        raise InputError(f"origin must hold 3 numbers, got shape {np.shape(origin)}")
    if np.size(spacing) != 1:
        raise InputError(f"spacing must be one number, got shape {np.shape(spacing)}")
    if not (np.isfinite(np.reshape(spacing, ())) and np.reshape(spacing, ()) > 0):
        raise InputError(f"spacing must be a positive number, got {np.reshape(spacing, ())}")
    if not np.all(np.isfinite(udf)):
        raise InputError("udf contains NaN or infinite values")
    if np.any(udf < 0):
        raise InputError("udf has negative values: an unsigned distance field is >= 0")
    return UDFGrid(udf.astype(np.float32), np.reshape(origin, 3).astype(np.float64),
                   float(np.reshape(spacing, ())))


def parse_iso(text, spacing: float):
    """'1.2h' → 1.2 voxels in world units; '0.004' → 0.004; None → None (automatic)."""
    if text is None:
        return None
    text = str(text).strip().lower()
    try:
        if text.endswith("h"):
            value = float(text[:-1]) * spacing
        else:
            value = float(text)
    except ValueError:
        raise InputError(f"--iso must be a number or a number of voxels like '1.0h', "
                         f"got {text!r}") from None
    if not (np.isfinite(value) and value > 0):
        raise InputError(f"--iso must be positive, got {text!r}")
    return value


def run(args) -> int:
    """Load the grid, extract the surface, write the mesh; return 0."""
    from ..io import write_mesh
    from ..meshing import MeshingSettings, extract_surface
    from .preflight import check_device, check_outputs, check_result

    check_outputs([args.output], [args.grid])
    check_device(args.device)
    if args.iterations is not None and args.iterations < 0:
        raise InputError(f"--iterations must be >= 0, got {args.iterations}")
    if args.min_component_faces < 0:
        raise InputError(f"--min-component-faces must be >= 0, got {args.min_component_faces}")
    grid = load_grid(args.grid)
    settings = MeshingSettings(iso=parse_iso(args.iso, grid.spacing), cut=not args.no_cut,
                               min_component_faces=args.min_component_faces, device=args.device)
    if args.iterations is not None:
        settings.iterations = args.iterations

    def progress(fraction, message):
        print(f"\r{100 * fraction:5.1f}% {message:<60}", end="", file=sys.stderr, flush=True)

    result = extract_surface(grid, settings, progress=progress)
    print(file=sys.stderr)
    for message in result.messages:
        print(f"warning: {message}", file=sys.stderr)
    for detail in result.details:
        print(f"  mesher: {detail}", file=sys.stderr)
    check_result(result.mesh, "meshing the grid")
    write_mesh(args.output, result.mesh)
    stages = ", ".join(f"{k} {v:.2f} s" for k, v in result.timings.items())
    print(f"{len(result.mesh.vertices)} vertices, {len(result.mesh.faces)} faces; iso "
          f"{result.iso / grid.spacing:.2f} voxels; {stages} (optimised on "
          f"{result.stats.get('optimize_device', 'cpu')})", file=sys.stderr)
    layers = ("twinned_faces", "layer_trees", "double_pairs", "seam_vertices")
    print("  layers: " + ", ".join(f"{k} {int(result.stats[k])}" for k in layers
                                   if k in result.stats), file=sys.stderr)
    return 0
