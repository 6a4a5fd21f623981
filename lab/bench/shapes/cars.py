"""Car-like multi-part models: the ShapeNet-Cars stand-in.

Like raw ShapeNet cars, a model is a soup of closed parts that overlap and are not unioned: a
rounded body and cabin, four tyres with hubs, thin mirrors, an optional spoiler on posts, an
antenna, and interior parts (seats, dashboard, steering wheel, floor pan) inside the shell.
Units are metres (x forward, y left, z up); the dataset moves the result to the unit frame.
"""

import numpy as np

from . import primitives as P


def _body(rng: np.random.Generator, length: float, width: float, height: float,
          clearance: float) -> P.Part:
    """Rounded body with a hood that drops toward the front and narrowed ends."""
    exponent = rng.uniform(3.0, 6.0)
    v, f = P.superellipsoid((0.0, 0.0, clearance + height / 2), (length / 2, width / 2, height / 2),
                            exponent, cells=28)
    x = v[:, 0] / (length / 2)
    top = np.clip((v[:, 2] - clearance - height / 2) / (height / 2), 0.0, 1.0)
    hood_drop, tail_drop = rng.uniform(0.1, 0.35), rng.uniform(0.0, 0.2)
    drop = np.where(x > 0, hood_drop * x ** 2, tail_drop * x ** 2)
    v = v.copy()
    v[:, 2] -= drop * top * height
    v[:, 1] *= 1.0 - rng.uniform(0.0, 0.12) * x ** 4
    return v, f


STYLES = {  # ranges: body height, clearance, cabin length and centre (/ car length), rear slant
    "coupe": ((0.45, 0.6), (0.1, 0.16), (0.3, 0.42), (-0.12, 0.0), (0.4, 0.7)),
    "sedan": ((0.5, 0.7), (0.12, 0.2), (0.4, 0.52), (-0.1, 0.02), (0.3, 0.55)),
    "hatchback": ((0.5, 0.7), (0.12, 0.2), (0.5, 0.6), (-0.22, -0.15), (0.1, 0.35)),
    "suv": ((0.7, 0.95), (0.2, 0.32), (0.6, 0.72), (-0.18, -0.1), (0.05, 0.25)),
}


def _cabin(rng: np.random.Generator, style: tuple, length: float, width: float,
           body_top: float) -> P.Part:
    """Greenhouse: a rounded block, narrower at the roof, with slanted windscreen and rear."""
    cab_len = length * rng.uniform(*style[2])
    cab_h = rng.uniform(0.35, 0.6)
    cab_x = length * rng.uniform(*style[3])
    zc = body_top + cab_h / 2 - 0.08
    half = (cab_len / 2, width * rng.uniform(0.4, 0.47), cab_h / 2)
    v, f = P.superellipsoid((0.0, 0.0, 0.0), half,
                            rng.uniform(3.0, 6.0), cells=18)
    up = (v[:, 2] + cab_h / 2) / cab_h  # 0 at the bottom, 1 at the roof
    front = v[:, 0] > 0
    slant = np.where(front, rng.uniform(0.3, 0.6), rng.uniform(*style[4]))
    v = v.copy()
    v[:, 0] *= 1.0 - slant * up
    v[:, 1] *= 1.0 - rng.uniform(0.05, 0.2) * up
    return v + (cab_x, 0.0, zc), f


def _wheels(rng: np.random.Generator, length: float, width: float, clearance: float) -> list:
    """Four tyres (boxy tori) with hubs that sit in the tyre hole with a small gap."""
    radius = rng.uniform(0.26, 0.36) + 0.4 * (clearance - 0.12)
    tyre_w = rng.uniform(0.18, 0.28)
    wheelbase = length * rng.uniform(0.55, 0.66)
    shift = length * rng.uniform(-0.03, 0.03)
    track = width / 2 - tyre_w * rng.uniform(0.35, 0.6)
    radial = radius * rng.uniform(0.18, 0.26)
    exponent = rng.uniform(3.0, 6.0)
    parts = []
    for x in (shift + wheelbase / 2, shift - wheelbase / 2):
        for side in (1.0, -1.0):
            centre = np.array([x, side * track, radius])
            parts.append(P.torus(centre, (0.0, 1.0, 0.0), radius - radial, radial, tyre_w / 2,
                                 exponent, around=48, section=14))
            hub_r = (radius - 2 * radial) * rng.uniform(0.85, 0.95)
            half = np.array([0.0, tyre_w * 0.4, 0.0])
            parts.append(P.cylinder(centre - half, centre + half, hub_r, around=24))
    return parts


def _thin_parts(rng: np.random.Generator, length: float, width: float, body_top: float,
                body: P.Part, cabin: P.Part) -> list:
    """Mirrors (1 cm plates on arms), spoiler plate on two posts, antenna rod."""
    cab_v = cabin[0]
    front_x = cab_v[:, 0].max()
    parts = []
    thick = rng.uniform(0.008, 0.012)
    mirror_half = (thick / 2, rng.uniform(0.06, 0.1), rng.uniform(0.04, 0.06))
    arm = rng.uniform(0.03, 0.08)
    for side in (1.0, -1.0):
        centre = (front_x - 0.05, side * (width / 2 + mirror_half[1] + arm), body_top + 0.1)
        parts.append(P.box(centre, mirror_half, 0.03))
        arm_y = side * (width / 2 + arm / 2 - 0.04)
        parts.append(P.box((front_x - 0.05, arm_y, body_top + 0.08),
                           (0.015, arm / 2 + 0.045, 0.008), 0.03))
    roof = cab_v[:, 2].max()
    if rng.random() < 0.7:
        rear = -length / 2 + rng.uniform(0.15, 0.3)
        near_rear = np.abs(body[0][:, 0] - rear) < 0.1
        deck = body[0][near_rear, 2].max()  # the body's top where the posts stand
        post_h = rng.uniform(0.06, 0.18)
        plate_z = deck + post_h
        parts.append(P.box((rear, 0.0, plate_z + thick / 2),
                           (rng.uniform(0.1, 0.16), width * rng.uniform(0.35, 0.45), thick / 2),
                           0.05))
        for side in (1.0, -1.0):
            y = side * width * 0.25
            parts.append(P.box((rear, y, plate_z - post_h / 2 - 0.01),
                               (0.02, 0.015, post_h / 2 + 0.01), 0.04))
    radius = rng.uniform(0.003, 0.006)
    base = np.array([cab_v[:, 0].min() * rng.uniform(0.2, 0.6), rng.uniform(-0.2, 0.2),
                     roof - 0.01])
    tip = base + np.array([-rng.uniform(0.0, 0.25), 0.0, rng.uniform(0.3, 0.7)])
    parts.append(P.cylinder(base, tip, radius, around=10, along=8))
    return parts


def _interior(rng: np.random.Generator, width: float, body_top: float, cabin: P.Part,
              clearance: float) -> list:
    """Seats, dashboard, steering wheel and a floor pan inside the shell."""
    cab_v = cabin[0]
    x0, x1 = cab_v[:, 0].min(), cab_v[:, 0].max()
    floor_z = clearance + 0.12
    parts = [P.box(((x0 + x1) / 2, 0.0, floor_z), ((x1 - x0) / 2, width * 0.4, 0.004), 0.1)]
    rows = [x1 - (x1 - x0) * rng.uniform(0.4, 0.5)]
    if rng.random() < 0.8:
        rows.append(x0 + (x1 - x0) * rng.uniform(0.25, 0.32))
    seat_z = floor_z + rng.uniform(0.15, 0.25)
    back_half = np.clip(0.3 * (cab_v[:, 2].max() - seat_z), 0.12, 0.3)  # backrest under the roof
    p = rng.uniform(3.0, 6.0)
    for row, x in enumerate(rows):
        ys = (-0.22 * width, 0.22 * width) if row == 0 or rng.random() < 0.5 else (0.0,)
        half_y = 0.12 * width if len(ys) == 2 else 0.38 * width
        for y in ys:
            parts.append(P.superellipsoid((x, y, seat_z), (0.24, half_y, 0.06), p, cells=6))
            back_x = x - 0.24
            back = P.superellipsoid((0, 0, 0), (0.05, half_y * 0.95, back_half), p, cells=6)
            tilt = rng.uniform(0.1, 0.3)
            c, s = np.cos(tilt), np.sin(tilt)
            rot = np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])
            parts.append(P.transform(back, rot, (back_x, y, seat_z + back_half)))
    dash_x = x1 - 0.12
    parts.append(P.superellipsoid((dash_x, 0.0, body_top - 0.05), (0.12, width * 0.42, 0.1),
                                  rng.uniform(3.0, 5.0), cells=8))
    wheel_axis = np.array([1.0, 0.0, 0.6])
    centre = (dash_x - 0.2, 0.22 * width * rng.choice([-1.0, 1.0]), body_top + 0.02)
    parts.append(P.torus(centre, wheel_axis, 0.17, 0.015, 0.015, 2.0, around=32, section=8))
    return parts


def make_car(seed: int) -> P.Part:
    """One car-like model in metres.

    Parameters
    ----------
    seed : every dimension, proportion and optional part is drawn from ``default_rng(seed)``

    Returns
    -------
    vertices : (V, 3) float64, metres
    faces : (F, 3) int64; every part is closed and outward-oriented; parts overlap
    """
    rng = np.random.default_rng(seed)
    style = STYLES[_style_name(rng)]
    length = rng.uniform(3.4, 5.2)
    width = rng.uniform(1.6, 2.0)
    height = rng.uniform(*style[0])
    clearance = rng.uniform(*style[1])
    body = _body(rng, length, width, height, clearance)
    body_top = clearance + height
    cabin = _cabin(rng, style, length, width, body_top)
    parts = [body, cabin]
    parts += _wheels(rng, length, width, clearance)
    parts += _thin_parts(rng, length, width, body_top, body, cabin)
    parts += _interior(rng, width, body_top, cabin, clearance)
    return P.concat(P.oriented_outward(p) for p in parts)


def _style_name(rng: np.random.Generator) -> str:
    names = sorted(STYLES)
    return names[int(rng.random() * len(names))]


def car_style(seed: int) -> str:
    """The body style (a key of ``STYLES``) ``make_car(seed)`` builds."""
    return _style_name(np.random.default_rng(seed))
