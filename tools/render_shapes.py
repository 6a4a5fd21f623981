"""Render a few benchmark shapes per domain, and scanned room clouds, to docs/benchmark_shapes.png.

Run from the repository root:  python tools/render_shapes.py [--out docs/benchmark_shapes.png]
Needs matplotlib (requirements-bench.txt), not part of the runtime.
"""

import argparse
import io
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from engine.sampling import face_areas_and_normals  # noqa: E402
from lab.bench.dataset import DOMAINS, make_input, make_shape, test_seeds  # noqa: E402

COLUMNS = 4
ROWS = len(DOMAINS) + 1  # one row per domain, then scanned room clouds
VIEWS = {"cars": (22, -55), "garments": (10, -70), "rooms": (35, 50)}
COLORS = {"cars": (0.55, 0.65, 0.85), "garments": (0.85, 0.6, 0.5), "rooms": (0.75, 0.75, 0.7)}
LIGHT = np.array([0.4, -0.5, 0.8]) / np.linalg.norm([0.4, -0.5, 0.8])


def _frame_axes(ax, points):
    """Tight limits with equal scale on every axis."""
    lo, hi = points.min(0), points.max(0)
    ax.set_xlim(lo[0], hi[0]), ax.set_ylim(lo[1], hi[1]), ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(np.maximum(hi - lo, 0.05), zoom=1.1)
    ax.set_axis_off()


def draw_mesh(ax, mesh, domain):
    """Flat-shaded triangles; one-sided sheets are lit from both sides."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    _, normals = face_areas_and_normals(mesh.vertices, mesh.faces)
    shade = 0.35 + 0.65 * np.abs(normals @ LIGHT)
    colors = np.clip(shade[:, None] * np.array(COLORS[domain])[None], 0, 1)
    polys = Poly3DCollection(mesh.vertices[mesh.faces], facecolors=colors, linewidths=0)
    ax.add_collection3d(polys)
    ax.view_init(*VIEWS[domain])
    _frame_axes(ax, mesh.vertices)


def draw_cloud(ax, points):
    """Points coloured by height, small markers so density differences show."""
    ax.scatter(points[:, 0], points[:, 1], points[:, 2], s=0.4, c=points[:, 2], cmap="viridis",
               depthshade=False, linewidths=0)
    ax.view_init(*VIEWS["rooms"])
    _frame_axes(ax, points)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=os.path.join("docs", "benchmark_shapes.png"))
    args = parser.parse_args()

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(4 * COLUMNS, 4 * ROWS))
    for row, domain in enumerate(DOMAINS):
        for col, seed in enumerate(test_seeds(domain, COLUMNS)):
            ax = fig.add_subplot(ROWS, COLUMNS, row * COLUMNS + col + 1, projection="3d")
            draw_mesh(ax, make_shape(domain, seed), domain)
            ax.set_title(f"{domain}, seed {seed}", fontsize=10)
    for col, seed in enumerate(test_seeds("rooms", COLUMNS)):
        ax = fig.add_subplot(ROWS, COLUMNS, len(DOMAINS) * COLUMNS + col + 1, projection="3d")
        cloud = make_input(make_shape("rooms", seed), "rooms", "clean", seed)
        draw_cloud(ax, cloud.points)
        ax.set_title(f"rooms input (virtual scan, 50k), seed {seed}", fontsize=10)
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.97, wspace=0, hspace=0.05)
    os.makedirs(os.path.dirname(args.out) or ".", exist_ok=True)
    buffer = io.BytesIO()
    fig.savefig(buffer, dpi=90)
    from PIL import Image  # a matplotlib dependency

    # a 256-colour palette keeps the committed picture small
    Image.open(buffer).convert("RGB").quantize(256).save(args.out, optimize=True)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
