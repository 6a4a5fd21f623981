"""How rough a query's parent patch is: the radius selector's view of noise.

Noise is what moves the best ball radius most (engine/weights/SELECTOR_CARD.md: the backbone's
error is lowest near 0.018 on clean scans and at 0.024 or beyond on noisy ones), and a point
encoder that sees a strided subset of the patch does not learn it from the coordinates alone.
Three numbers per patch, all scale-free (distances in units of the parent radius R):

- **thickness**: sqrt(smallest / summed eigenvalue of the patch's covariance), 0 on a plane,
  about 0.58 for an isotropic blob; it also grows with curvature;
- **quadric residual**: the root-mean-square height residual of a least-squares quadric
  h = a u² + b uv + c v² + d u + e v + f in the patch's principal frame, divided by R. A quadric
  follows smooth curvature, so what remains is mostly noise (and creases or a second sheet).
- **split**: how well the points' heights above the patch's plane fall into two groups, the
  largest share of their variance that lies between the two sides of one cut (Otsu's
  criterion): near 1 for two sheets a little way apart (two layers of cloth), about 2/π for
  Gaussian noise. It tells a second sheet from noise, which the first two numbers do not.

Patches with fewer than MIN_POINTS points get 0 for all three (too few to fit a quadric); the
selector also reads the point count. The selector passes its strided parent patch (16 of the
64 nearest points) and its 16 nearest points: the points are already gathered, and each fit
costs a few microseconds per query.
"""

import numpy as np

from .cpu_threads import run_in_threads

MIN_POINTS = 7       # a quadric has 6 coefficients
_CHUNK = 512         # queries per vectorised step: the arrays stay in cache
_RIDGE = 1e-6        # keeps the quadric's normal equations solvable on degenerate patches
_FLAT = 1e-4         # heights (in R) spread less than this are a plane's rounding
ROUGHNESS_FEATURES = 3


def patch_roughness(rel: np.ndarray, mask: np.ndarray, threads: int = 1) -> np.ndarray:
    """[thickness, quadric residual, split] per patch (the first two in units of the patch
    radius); (Q, ROUGHNESS_FEATURES) float32.

    Parameters
    ----------
    rel : (Q, M, 3) patch points relative to their query, divided by the radius (the patch
        contract of :mod:`engine.patches`)
    mask : (Q, M) bool, which entries of ``rel`` are points (the rest is padding)
    threads : CPU threads over the chunks of patches (each patch's answer is the same either way)
    """
    mask = np.asarray(mask, dtype=bool)
    counts = mask.sum(axis=1)
    out = np.zeros((len(rel), ROUGHNESS_FEATURES), dtype=np.float32)
    rows = np.flatnonzero(counts >= MIN_POINTS)

    def fit(start: int) -> None:
        part = rows[start:start + _CHUNK]
        out[part] = _roughness(np.asarray(rel[part], dtype=np.float32),
                               mask[part].astype(np.float32))

    run_in_threads(fit, range(0, len(rows), _CHUNK), threads)
    return out


def _roughness(rel: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """Thickness, quadric residual and split of (b, m, 3) patches whose padding has weight 0."""
    count = weight.sum(axis=1)
    centroid = np.matmul(weight[:, None, :], rel)[:, 0] / count[:, None]
    centred = (rel - centroid[:, None]) * weight[..., None]
    covariance = np.matmul(centred.transpose(0, 2, 1), centred).astype(np.float64)
    eigenvalues, eigenvectors = np.linalg.eigh(covariance)  # ascending: column 0 is the normal
    thickness = np.sqrt(np.maximum(eigenvalues[:, 0], 0.0)
                        / np.maximum(eigenvalues.sum(axis=1), 1e-18))
    local = np.matmul(centred, eigenvectors.astype(np.float32))
    height, u, v = local[..., 0], local[..., 1], local[..., 2]
    design = np.empty(rel.shape[:2] + (6,), dtype=np.float32)  # padding rows are all 0
    design[..., 0] = u * u
    design[..., 1] = u * v
    design[..., 2] = v * v
    design[..., 3] = u
    design[..., 4] = v
    design[..., 5] = weight
    transposed = design.transpose(0, 2, 1)
    normal = np.matmul(transposed, design).astype(np.float64) + _RIDGE * np.eye(6)
    projected = np.matmul(transposed, height[..., None]).astype(np.float64)
    coefficients = np.linalg.solve(normal, projected)
    # least squares: residual sum of squares = h.h - c.(A^T h)
    squares = np.einsum("bm,bm->b", height, height).astype(np.float64)
    residual = np.maximum(squares - (coefficients * projected)[:, :, 0].sum(axis=1), 0.0)
    return np.column_stack([thickness, np.sqrt(residual / count),
                            _split(height.astype(np.float64), weight > 0, count)])


def _split(height: np.ndarray, real: np.ndarray, count: np.ndarray) -> np.ndarray:
    """Otsu's between-groups share of the variance of each row's ``real`` heights (mean 0): with
    S_k the sum of the k lowest, a cut after them leaves S_k² n / (k (n - k)) between the two."""
    ordered = np.sort(np.where(real, height, np.inf), axis=1)
    ordered = np.where(np.isfinite(ordered), ordered, 0.0)  # padding last, adding nothing
    below = np.cumsum(ordered, axis=1)[:, :-1]
    k = np.arange(1, height.shape[1])[None, :]
    n = count[:, None].astype(np.float64)
    between = np.where(k < n, below ** 2 * n / (k * np.maximum(n - k, 1)), 0.0).max(axis=1)
    total = np.einsum("bm,bm->b", ordered, ordered)
    return between / np.maximum(total, _FLAT ** 2 * count)
