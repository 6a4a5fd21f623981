"""Synthetic local patches with exact unsigned distances, drawn on the fly in vectorised numpy.

Everything is in patch units: the ball radius r is 1, so a patch is what
:func:`engine.patches.gather_patches` returns divided by r. One patch is made like this:

1. A surface from one family (below), written as one or two height fields z = f(x, y),
   optionally truncated by a half-plane in (x, y) (an open boundary).
2. A foot point on the surface near the feature at the origin and a query
   q = foot + s * u, u a uniform random direction, 0 <= s <= 1.05.
3. Surface samples around q at a random density (area-correct, optionally uneven), optional
   Gaussian noise and a few outliers in the ball.
4. The patch contract: the (up to) MAX_POINTS nearest samples within distance 1 of q, as
   rel = p - q sorted by distance, zero-padded, with a mask of the real rows.
5. Ground truth: the exact distance from q to the (truncated) generating surface, by a coarse
   grid over the parameter domain plus five levels of local grid refinement around the best
   coarse candidates (accurate to about 1e-4 patch units, see the tests).
6. A uniform random rotation of rel (normalised Gaussian quaternion).

Families (LoSF-UDF's smooth and sharp families, plus boundaries and thin structures):
plane, cylinder, quadric (z = (k1 x^2 + k2 y^2) / 2, |k| <= 2 per radius), boundary (a plane,
cylinder or quadric cut by a line), crease (z = -h|x|), cusp (z = -h sqrt(x^2 + y^2)),
corner (3- or 4-sided pyramid), saddle (z = -h max(|x|,|y|) sign~(xy)) and two_sheets (two
roughly parallel quadrics a gap < 1 apart).
"""

from typing import Callable, Dict, List, Optional, Tuple

import numpy as np

from engine.patches import MAX_POINTS

FAMILIES = ("plane", "cylinder", "quadric", "boundary", "crease", "cusp", "corner", "saddle",
            "two_sheets")
# Relative frequency of each family in training and validation batches.
FAMILY_WEIGHTS = {"plane": 0.08, "cylinder": 0.08, "quadric": 0.16, "boundary": 0.14,
                  "crease": 0.12, "cusp": 0.08, "corner": 0.10, "saddle": 0.08,
                  "two_sheets": 0.16}

MAX_QUERY_OFFSET = 1.05     # s in q = foot + s u
MAX_UDF = 1.25              # patches whose true distance exceeds this are dropped
SAMPLE_HALF_WIDTH = 1.05    # surface samples are drawn over q_xy +- this (covers the ball)
CANDIDATES = 640            # surface candidates drawn per sheet and patch before thinning
GT_HALF_WIDTH = 1.6         # the ground-truth search covers q_xy +- this (> MAX_UDF)
GT_COARSE = 33              # coarse ground-truth grid: GT_COARSE^2 parameter samples
GT_CANDIDATES = 4           # coarse minima refined locally
GT_LEVELS = 5               # refinement levels, each 4x finer (9 x 9 local grid)
NOISE_PROBABILITY = 0.3
NOISE_SIGMA_MAX = 0.15      # patch units; 0.0025 / 0.018 = 0.14 is the benchmark's noise
OUTLIER_PROBABILITY = 0.1
UNEVEN_PROBABILITY = 0.3

Height = Callable[[np.ndarray, np.ndarray], np.ndarray]
Keep = Optional[Callable[[np.ndarray, np.ndarray], np.ndarray]]


class Sheet:
    """One height-field surface per patch of a batch of n patches.

    ``height(x, y)`` and ``keep(x, y)`` take (n, m) arrays of parameter coordinates and return
    (n, m) heights and (n, m) booleans (False where the surface is cut away); per-patch
    parameters are captured as (n, 1) arrays so they broadcast.
    """

    def __init__(self, height: Height, keep: Keep = None):
        self.height = height
        self.keep = keep

    def points(self, x: np.ndarray, y: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """(n, m, 3) surface points at parameters (x, y) and the (n, m) keep mask."""
        z = self.height(x, y)
        keep = np.ones(x.shape, dtype=bool) if self.keep is None else self.keep(x, y)
        return np.stack([x, y, z], axis=-1), keep


# ----------------------------------------------------------------------------- ground truth

def _squared_distances(sheet: Sheet, q: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(n, m) squared distances from q (n, 3) to the sheet at parameters (x, y); inf if cut."""
    p, keep = sheet.points(x, y)
    d2 = np.sum((p - q[:, None, :]) ** 2, axis=-1)
    return np.where(keep, d2, np.inf)


def height_field_distance(q: np.ndarray, sheet: Sheet, half_width: float = GT_HALF_WIDTH,
                          coarse: int = GT_COARSE, candidates: int = GT_CANDIDATES,
                          levels: int = GT_LEVELS) -> np.ndarray:
    """Distance from each query to its (possibly truncated) height-field sheet.

    Searches the parameter square q_xy +- half_width: a coarse grid, then ``levels`` rounds of a
    9 x 9 grid spanning +- one previous spacing around each of the ``candidates`` best coarse
    points. Exact up to the final spacing (coarse spacing / 4^levels) for any surface point
    within ``half_width`` of q; farther points are not seen.

    Parameters
    ----------
    q : (n, 3) float64 queries (patch units).
    sheet : the n surfaces.

    Returns
    -------
    (n,) float64 distances (inf when the whole searched square is cut away).
    """
    n = q.shape[0]
    t = np.linspace(-half_width, half_width, coarse)
    gx, gy = np.meshgrid(t, t, indexing="ij")
    x = q[:, 0:1] + gx.reshape(1, -1)
    y = q[:, 1:2] + gy.reshape(1, -1)
    d2 = _squared_distances(sheet, q, x, y)
    best = np.argpartition(d2, candidates - 1, axis=1)[:, :candidates]
    cx = np.take_along_axis(x, best, axis=1)          # (n, K) candidate centres
    cy = np.take_along_axis(y, best, axis=1)
    spacing = t[1] - t[0]
    local = np.linspace(-1.0, 1.0, 9)
    lx, ly = [a.reshape(1, 1, -1) for a in np.meshgrid(local, local, indexing="ij")]
    result = d2.min(axis=1)
    for _ in range(levels):
        x = (cx[:, :, None] + spacing * lx).reshape(n, -1)   # (n, K * 81)
        y = (cy[:, :, None] + spacing * ly).reshape(n, -1)
        d2 = _squared_distances(sheet, q, x, y).reshape(n, candidates, -1)
        arg = np.argmin(d2, axis=2)
        cx = np.take_along_axis(x.reshape(n, candidates, -1), arg[..., None], axis=2)[..., 0]
        cy = np.take_along_axis(y.reshape(n, candidates, -1), arg[..., None], axis=2)[..., 0]
        result = np.minimum(result, d2.min(axis=(1, 2)))
        spacing /= 4.0
    return np.sqrt(result)


# ----------------------------------------------------------------------------- families

def _quadric(k1: np.ndarray, k2: np.ndarray, offset=0.0, slope=0.0) -> Height:
    return lambda x, y: offset + slope * x + 0.5 * (k1 * x * x + k2 * y * y)


def _curvature(rng: np.random.Generator, n: int, limit: float) -> np.ndarray:
    """(n, 1) signed curvatures in [-limit, limit], denser near 0 (|k| = limit * U^1.5)."""
    return (rng.choice([-1.0, 1.0], size=(n, 1)) * limit * rng.random((n, 1)) ** 1.5)


def _smooth_sheet(kind: str, rng: np.random.Generator, n: int) -> Height:
    if kind == "plane":
        zero = np.zeros((n, 1))
        return _quadric(zero, zero)
    if kind == "cylinder":
        k = _curvature(rng, n, 2.0)
        k = np.where(np.abs(k) < 0.05, 0.05 * np.sign(k), k)
        return _quadric(k, np.zeros((n, 1)))
    return _quadric(_curvature(rng, n, 2.0), _curvature(rng, n, 2.0))


def make_surfaces(family: str, rng: np.random.Generator, n: int
                  ) -> Tuple[List[Sheet], float]:
    """The sheets of n random surfaces of one family and the foot-point disc radius.

    The foot point of each query is drawn uniformly in a disc of that radius around the origin
    (where the sharp feature, if any, lies) on one of the sheets.
    """
    if family in ("plane", "cylinder", "quadric"):
        return [Sheet(_smooth_sheet(family, rng, n))], 0.3
    if family == "boundary":
        kind = rng.choice(3, size=(n, 1), p=[0.4, 0.3, 0.3])
        bases = [_smooth_sheet(k, rng, n) for k in ("plane", "cylinder", "quadric")]

        def base(x, y):
            return np.choose(np.broadcast_to(kind, x.shape), [b(x, y) for b in bases])
        angle = rng.uniform(0, 2 * np.pi, (n, 1))
        nx, ny = np.cos(angle), np.sin(angle)
        cut = rng.uniform(-0.7, 0.7, (n, 1))
        return [Sheet(base, lambda x, y: nx * x + ny * y <= cut)], 0.5
    if family == "crease":
        h = rng.uniform(0.1, 5.0, (n, 1))
        return [Sheet(lambda x, y: -h * np.abs(x))], 0.6
    if family == "cusp":
        h = rng.uniform(0.2, 5.0, (n, 1))
        return [Sheet(lambda x, y: -h * np.sqrt(x * x + y * y))], 0.5
    if family == "corner":
        h = rng.uniform(0.2, 5.0, (n, 1))
        sides = rng.choice([3, 4], size=(n, 1))
        phase = rng.uniform(0, 2 * np.pi, (n, 1))

        def corner(x, y):
            g = np.full(x.shape, -np.inf)
            for j in range(4):
                theta = phase + 2 * np.pi * j / sides
                g = np.where(j < sides, np.maximum(g, np.cos(theta) * x + np.sin(theta) * y), g)
            return -h * g
        return [Sheet(corner)], 0.5
    if family == "saddle":
        h = rng.uniform(0.05, 3.0, (n, 1))
        return [Sheet(lambda x, y: -h * np.maximum(np.abs(x), np.abs(y))
                      * np.clip(x * y / 0.2, -1.0, 1.0))], 0.5
    if family == "two_sheets":
        gap = rng.uniform(0.08, 1.0, (n, 1))
        lower = _quadric(_curvature(rng, n, 0.7), _curvature(rng, n, 0.7))
        upper = _quadric(_curvature(rng, n, 0.7), _curvature(rng, n, 0.7), offset=gap,
                         slope=rng.uniform(-0.3, 0.3, (n, 1)))
        return [Sheet(lower), Sheet(upper)], 0.4
    raise ValueError(f"unknown family {family!r}")


# ----------------------------------------------------------------------------- sampling

def _random_rotations(rng: np.random.Generator, n: int) -> np.ndarray:
    """(n, 3, 3) rotations uniform on SO(3) (normalised Gaussian quaternions)."""
    w, x, y, z = (rng.standard_normal((4, n)) / 1.0)
    norm = np.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / norm, x / norm, y / norm, z / norm
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], axis=1)


def _density(rng: np.random.Generator, n: int) -> np.ndarray:
    """(n, 1) surface densities (points per unit^2 of patch area).

    Expressed as the count a flat disc through the ball centre would hold (density * pi):
    45 % typical (U(18, 40), LoSF's ~25-30 at r = 0.018 with 50 k points), 15 % sparse
    (U(3, 10), 10 k-point inputs) and 40 % log-uniform on [1.5, 120].
    """
    u = rng.random(n)
    per_ball = np.where(u < 0.45, rng.uniform(18, 40, n),
                        np.where(u < 0.60, rng.uniform(3, 10, n),
                                 np.exp(rng.uniform(np.log(1.5), np.log(120), n))))
    return (per_ball / np.pi)[:, None]


def _sample_sheet(sheet: Sheet, q: np.ndarray, density: np.ndarray, uneven: np.ndarray,
                  rng: np.random.Generator) -> Tuple[np.ndarray, np.ndarray]:
    """Area-correct random samples of a sheet around q: (n, CANDIDATES, 3) and a (n, C) mask."""
    n = q.shape[0]
    w = SAMPLE_HALF_WIDTH
    x = q[:, 0:1] + rng.uniform(-w, w, (n, CANDIDATES))
    y = q[:, 1:2] + rng.uniform(-w, w, (n, CANDIDATES))
    p, keep = sheet.points(x, y)
    eps = 1e-4
    fx = (sheet.height(x + eps, y) - sheet.height(x - eps, y)) / (2 * eps)
    fy = (sheet.height(x, y + eps) - sheet.height(x, y - eps)) / (2 * eps)
    area = np.sqrt(1.0 + fx * fx + fy * fy)          # surface area per parameter area
    accept = density * (2 * w) ** 2 * area / CANDIDATES
    # Uneven sampling: density modulated by a random linear ramp across the patch.
    angle = rng.uniform(0, 2 * np.pi, (n, 1))
    ramp = np.clip(0.55 + 0.6 * (np.cos(angle) * (x - q[:, 0:1]) + np.sin(angle) * (y - q[:, 1:2])),
                   0.05, 1.0)
    accept = np.where(uneven[:, None], accept * ramp, accept)
    keep &= rng.random((n, CANDIDATES)) < accept
    return p, keep


def _make_family_batch(family: str, n: int, rng: np.random.Generator) -> Dict[str, np.ndarray]:
    """n candidate patches of one family (some may be empty or too far; the caller filters)."""
    sheets, foot_radius = make_surfaces(family, rng, n)
    # Query: a foot point on a random sheet, offset by s in a uniform random direction.
    radius = foot_radius * np.sqrt(rng.random((n, 1)))
    angle = rng.uniform(0, 2 * np.pi, (n, 1))
    fx, fy = radius * np.cos(angle), radius * np.sin(angle)
    which = rng.integers(0, len(sheets), n)
    fz = np.zeros((n, 1))
    for i, sheet in enumerate(sheets):
        fz = np.where(which[:, None] == i, sheet.height(fx, fy), fz)
    direction = rng.standard_normal((n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    s = MAX_QUERY_OFFSET * rng.random((n, 1)) ** 1.3
    q = np.concatenate([fx, fy, fz], axis=1) + s * direction

    udf = np.min([height_field_distance(q, sheet) for sheet in sheets], axis=0)

    density = _density(rng, n)
    uneven = rng.random(n) < UNEVEN_PROBABILITY
    parts = [_sample_sheet(sheet, q, density, uneven, rng) for sheet in sheets]
    points = np.concatenate([p for p, _ in parts], axis=1)
    valid = np.concatenate([k for _, k in parts], axis=1)

    noisy = rng.random(n) < NOISE_PROBABILITY
    sigma = np.where(noisy, rng.uniform(0.0, NOISE_SIGMA_MAX, n), 0.0)
    points = points + sigma[:, None, None] * rng.standard_normal(points.shape)

    # Outliers: 1-3 points uniform in the ball around q.
    outlier = rng.random(n) < OUTLIER_PROBABILITY
    extra = rng.standard_normal((n, 3, 3))
    extra *= (rng.random((n, 3, 1)) ** (1 / 3)) / np.linalg.norm(extra, axis=2, keepdims=True)
    extra_valid = outlier[:, None] & (np.arange(3)[None, :] < rng.integers(1, 4, (n, 1)))
    rel = np.concatenate([points - q[:, None, :], extra], axis=1)
    valid = np.concatenate([valid, extra_valid], axis=1)

    dist = np.where(valid, np.linalg.norm(rel, axis=2), np.inf)
    inside = dist <= 1.0
    count_in_ball = inside.sum(axis=1)
    order = np.argsort(dist, axis=1)[:, :MAX_POINTS]
    rel = np.take_along_axis(rel, order[..., None], axis=1)
    mask = np.take_along_axis(inside, order, axis=1)
    rel = np.where(mask[..., None], rel, 0.0)
    rel = np.einsum("nij,nkj->nki", _random_rotations(rng, n), rel)
    return {"rel": rel.astype(np.float32), "mask": mask, "udf": udf.astype(np.float32),
            "family": np.full(n, FAMILIES.index(family), dtype=np.int8),
            "count_in_ball": count_in_ball.astype(np.int32),
            "noise": sigma.astype(np.float32), "outliers": outlier}


def generate_patches(count: int, rng: np.random.Generator, chunk: int = 1024,
                     family_weights: Optional[Dict[str, float]] = None) -> Dict[str, np.ndarray]:
    """``count`` random patches, families mixed by ``family_weights``, in random order.

    Only patches with at least one real point and a true distance <= MAX_UDF are kept.

    Returns
    -------
    dict with
        rel : (count, MAX_POINTS, 3) float32, patch points (p - q) / r, nearest first, zero-padded
        mask : (count, MAX_POINTS) bool, real rows
        udf : (count,) float32, true unsigned distance / r
        family : (count,) int8, index into FAMILIES
        count_in_ball : (count,) int32, samples within the ball before the MAX_POINTS cut
        noise : (count,) float32, Gaussian noise sigma of the patch (patch units, 0 = clean)
        outliers : (count,) bool, whether outliers were added
    """
    weights = dict(FAMILY_WEIGHTS if family_weights is None else family_weights)
    names = [f for f in FAMILIES if weights.get(f, 0) > 0]
    p = np.array([weights[f] for f in names], dtype=np.float64)
    p /= p.sum()
    out: List[Dict[str, np.ndarray]] = []
    have = 0
    while have < count:
        want = min(chunk, int((count - have) * 1.25) + 16)
        per_family = rng.multinomial(want, p)
        for family, k in zip(names, per_family):
            if k == 0:
                continue
            batch = _make_family_batch(family, int(k), rng)
            good = batch["mask"][:, 0] & (batch["udf"] <= MAX_UDF)
            batch = {key: value[good] for key, value in batch.items()}
            out.append(batch)
            have += int(good.sum())
    merged = {key: np.concatenate([b[key] for b in out])[:] for key in out[0]}
    order = rng.permutation(len(merged["udf"]))[:count]
    return {key: value[order] for key, value in merged.items()}


def nearest_point_baseline(rel: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(B,) distance to the nearest real patch point: the trivial UDF estimate (patch units)."""
    dist = np.linalg.norm(rel, axis=2)
    return np.where(mask, dist, np.inf).min(axis=1)
