"""Garment-like open surfaces: the DeepFashion3D stand-in.

A garment is a few open parametric tubes (the cloth, with boundary loops at waist, hem, neck and
cuffs) plus close layers a few millimetres off the cloth (waistband, collar, hem band, pockets).
Folds come at three scales: low-frequency wobble, medium folds growing toward the hem, fine
wrinkles. Three types: skirt (1 tube), shirt (torso + 2 unstitched overlapping sleeves), trousers
(waist + 2 legs). Units are metres (z up); the dataset moves the result to the unit frame.
"""

from typing import Callable, Tuple

import numpy as np

from . import primitives as P

GARMENT_TYPES = ("skirt", "shirt", "trousers")


class Tube:
    """One open tube of cloth: a profile (centre height, radius) along v with folds around it.

    Parameters
    ----------
    profile : v (M,) in [0, 1] -> (z (M,), radius (M,)) in metres, local frame (hangs along -z)
    ellipse : depth / width ratio of the cross-section
    rng : draws the folds
    fold_scale : metres; amplitude of the medium folds at the bottom end
    rotation, origin : (3, 3), (3,) placing the local frame in the garment
    """

    def __init__(self, profile: Callable[[np.ndarray], Tuple[np.ndarray, np.ndarray]],
                 ellipse: float, rng: np.random.Generator, fold_scale: float,
                 rotation: np.ndarray = np.eye(3), origin=(0.0, 0.0, 0.0)):
        self.profile, self.ellipse = profile, ellipse
        self.rotation, self.origin = rotation, np.asarray(origin, dtype=np.float64)
        terms = []  # (k, amplitude, phase, drift along v, v-weight exponent)
        for _ in range(2):
            terms.append((rng.integers(1, 4), fold_scale * rng.uniform(0.3, 0.6),
                          rng.uniform(0, 2 * np.pi), rng.uniform(-2, 2), 0.0))
        for _ in range(3):
            terms.append((rng.integers(4, 11), fold_scale * rng.uniform(0.4, 1.0),
                          rng.uniform(0, 2 * np.pi), rng.uniform(-3, 3), 1.0))
        for _ in range(3):
            terms.append((rng.integers(12, 29), fold_scale * rng.uniform(0.1, 0.25),
                          rng.uniform(0, 2 * np.pi), rng.uniform(-6, 6), 0.5))
        self.terms = terms
        self.ripple = (rng.uniform(4, 10), fold_scale * rng.uniform(0.05, 0.15),
                       rng.uniform(0, 2 * np.pi))

    def points(self, theta: np.ndarray, v: np.ndarray, offset: float = 0.0) -> np.ndarray:
        """Surface points (len(theta), len(v), 3), pushed ``offset`` metres outward."""
        th, vv = np.meshgrid(theta, v, indexing="ij")
        z, radius = self.profile(v)
        r = radius[None, :] + offset
        for k, amp, phase, drift, power in self.terms:
            r = r + amp * (0.15 + vv) ** power * np.sin(k * th + phase + drift * vv)
        freq, amp, phase = self.ripple
        r = r + amp * np.sin(2 * np.pi * freq * vv + phase) * np.cos(th)
        local = np.stack([r * np.cos(th), self.ellipse * r * np.sin(th),
                          np.broadcast_to(z[None, :], th.shape)], -1)
        return local @ self.rotation.T + self.origin

    def mesh(self, around: int, along: int, v0: float = 0.0, v1: float = 1.0,
             offset: float = 0.0) -> P.Part:
        """The full tube (or a band v0..v1 of it) as an open mesh with outward normals."""
        theta = np.linspace(0.0, 2 * np.pi, around, endpoint=False)
        pts = self.points(theta, np.linspace(v0, v1, along), offset)
        return pts.reshape(-1, 3), P.grid_faces(around, along, wrap_u=True)[:, [0, 2, 1]]

    def patch(self, theta0: float, width: float, v0: float, height: float, offset: float,
              cells: int = 14) -> P.Part:
        """A pocket: a small open patch of the tube, ``offset`` metres off the cloth."""
        theta = np.linspace(theta0, theta0 + width, cells)
        pts = self.points(theta, np.linspace(v0, v0 + height, cells), offset)
        return pts.reshape(-1, 3), P.grid_faces(cells, cells)[:, [0, 2, 1]]


def _smoothstep(t: np.ndarray) -> np.ndarray:
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3 - 2 * t)


def _layers(rng: np.random.Generator, tube: Tube, around: int, top: bool, bottom: bool,
            pockets: int, pocket_v: Tuple[float, float]) -> list:
    """Bands at the ends and pockets, each 2-6 mm off the cloth."""
    parts = []
    if top:
        parts.append(tube.mesh(around, 6, 0.0, rng.uniform(0.04, 0.08), rng.uniform(0.002, 0.006)))
    if bottom:
        start = 1.0 - rng.uniform(0.04, 0.08)
        parts.append(tube.mesh(around, 6, start, 1.0, rng.uniform(0.002, 0.006)))
    for _ in range(pockets):
        theta0, width, v0 = rng.uniform(0, 2 * np.pi), rng.uniform(0.4, 0.8), rng.uniform(*pocket_v)
        height, offset = rng.uniform(0.08, 0.15), rng.uniform(0.002, 0.005)
        parts.append(tube.patch(theta0, width, v0, height, offset))
    return parts


def _skirt(rng: np.random.Generator) -> list:
    waist, length = rng.uniform(0.14, 0.19), rng.uniform(0.35, 0.9)
    hem, power = waist * rng.uniform(1.15, 2.2), rng.uniform(0.6, 1.5)

    def profile(v):
        return -length * v, waist + (hem - waist) * v ** power

    tube = Tube(profile, rng.uniform(0.75, 0.9), rng, rng.uniform(0.008, 0.02) * hem / waist)
    along = int(np.clip(length / 0.01, 30, 90))
    return [tube.mesh(192, along)] + _layers(rng, tube, 192, rng.random() < 0.7, rng.random() < 0.5,
                                             rng.integers(0, 3), (0.1, 0.4))


def _shirt(rng: np.random.Generator) -> list:
    neck, chest = rng.uniform(0.07, 0.09), rng.uniform(0.16, 0.21)
    hem, length = chest * rng.uniform(0.9, 1.2), rng.uniform(0.55, 0.85)
    drop, v_sh = rng.uniform(0.04, 0.08), 0.15

    def profile(v):
        s = _smoothstep(v / v_sh)
        below = np.clip((v - v_sh) / (1 - v_sh), 0.0, 1.0)
        z = -drop * s - (length - drop) * below
        r = neck + (chest - neck) * s + (hem - chest) * below
        return z, r

    ellipse = rng.uniform(0.6, 0.75)
    torso = Tube(profile, ellipse, rng, rng.uniform(0.006, 0.014))
    parts = [torso.mesh(160, 80)]
    sleeve_len = rng.uniform(0.2, 0.3) if rng.random() < 0.4 else rng.uniform(0.5, 0.65)
    top, cuff = rng.uniform(0.07, 0.09), rng.uniform(0.045, 0.07)
    angle = rng.uniform(np.radians(15), np.radians(60))
    along = int(np.clip(sleeve_len / 0.012, 16, 55))
    for side in (1.0, -1.0):
        direction = np.array([side * np.sin(angle), 0.0, -np.cos(angle)])
        start = np.array([side * chest * 0.85, 0.0, -drop - 0.04]) - 0.05 * direction
        sleeve = Tube(lambda v: (-sleeve_len * v, top + (cuff - top) * v), rng.uniform(0.8, 1.0),
                      rng, rng.uniform(0.003, 0.008), P.frame_from_axis(-direction), start)
        parts.append(sleeve.mesh(64, along))
        if rng.random() < 0.5:
            parts.append(sleeve.mesh(64, 5, 0.92, 1.0, rng.uniform(0.002, 0.005)))
    parts += _layers(rng, torso, 160, rng.random() < 0.8, rng.random() < 0.5, rng.integers(0, 2),
                     (0.2, 0.35))
    return parts


def _trousers(rng: np.random.Generator) -> list:
    waist, hip = rng.uniform(0.17, 0.21), rng.uniform(0.22, 0.3)
    ellipse = rng.uniform(0.7, 0.8)
    top = Tube(lambda v: (-hip * v, waist * (1 + 0.08 * v)), ellipse, rng,
               rng.uniform(0.004, 0.008))
    parts = [top.mesh(160, 25)]
    length = rng.uniform(0.3, 0.45) if rng.random() < 0.3 else rng.uniform(0.75, 1.05)
    leg_top, leg_bottom = rng.uniform(0.1, 0.115), rng.uniform(0.05, 0.1)
    spread = rng.uniform(0.0, np.radians(6))
    along = int(np.clip(length / 0.012, 25, 85))
    for side in (1.0, -1.0):
        direction = np.array([side * np.sin(spread), 0.0, -np.cos(spread)])
        start = np.array([side * rng.uniform(0.08, 0.1), 0.0, -hip + 0.06])
        leg = Tube(lambda v: (-length * v, leg_top + (leg_bottom - leg_top) * v),
                   rng.uniform(0.85, 1.0), rng, rng.uniform(0.004, 0.012),
                   P.frame_from_axis(-direction), start)
        parts.append(leg.mesh(96, along))
        parts += _layers(rng, leg, 96, False, rng.random() < 0.5, rng.integers(0, 2), (0.1, 0.5))
    parts += _layers(rng, top, 160, rng.random() < 0.8, False, rng.integers(0, 3), (0.1, 0.4))
    return parts


def make_garment(seed: int) -> P.Part:
    """One garment-like open surface in metres.

    Parameters
    ----------
    seed : the type and every parameter are drawn from ``default_rng(seed)``

    Returns
    -------
    vertices : (V, 3) float64, metres
    faces : (F, 3) int64; open tubes and patches, at least two boundary loops
    """
    rng = np.random.default_rng(seed)
    kind = GARMENT_TYPES[rng.integers(len(GARMENT_TYPES))]
    builders = {"skirt": _skirt, "shirt": _shirt, "trousers": _trousers}
    return P.concat(builders[kind](rng))


def garment_type(seed: int) -> str:
    """The garment type ``make_garment(seed)`` builds."""
    rng = np.random.default_rng(seed)
    return GARMENT_TYPES[rng.integers(len(GARMENT_TYPES))]
