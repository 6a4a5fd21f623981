"""``python -m engine metrics PRED GT``: score a predicted mesh against a ground truth.

Prints one JSON object on stdout (keys of :func:`engine.metrics.evaluate`). Non-finite values
(the Chamfer distances of an empty prediction) are written as ``null`` so the output stays strict
JSON; ``"empty": true`` says why.
"""

import json
import math


def add_arguments(parser) -> None:
    """Register the command's arguments on an ``argparse`` parser."""
    parser.add_argument("pred", help="predicted mesh file (.ply, .obj, .off, ...)")
    parser.add_argument("gt", help="ground-truth mesh file")
    parser.add_argument("--samples", type=int, default=100_000,
                        help="area-weighted samples per mesh (default 100000)")
    parser.add_argument("--seed", type=int, default=0, help="sampling seed (default 0)")
    parser.add_argument("--layer-distance", type=float, default=1.0 / 256,
                        help="unit-frame distance within which an opposite-facing sheet counts "
                             "as a double layer (default 1/256, one grid spacing at 256)")


def run(args) -> int:
    """Read both meshes, score them in the GT's unit frame, print the JSON; return 0."""
    from ..io import read_mesh
    from ..metrics import evaluate

    pred = read_mesh(args.pred)
    gt = read_mesh(args.gt)
    result = evaluate(pred, gt, samples=args.samples, seed=args.seed,
                      layer_distance=args.layer_distance)  # in the GT's unit frame
    strict = {key: (None if isinstance(value, float) and not math.isfinite(value) else value)
              for key, value in result.items()}
    print(json.dumps(strict, allow_nan=False))
    return 0
