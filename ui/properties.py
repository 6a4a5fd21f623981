"""The panel's settings, stored on the scene (``scene.udf_reconstruction``) and saved with the file.

They mirror :class:`engine.settings.ReconstructSettings` one to one; :func:`to_settings` turns them
into the dataclass every entry point (panel, batch script, CLI) hands to the engine.
"""

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty

from ..engine.settings import ReconstructSettings

_DEFAULTS = ReconstructSettings()

RADIUS_MODE_ITEMS = (
    ("fixed", "Fixed",
     "One ball radius everywhere. Fast and predictable; thin parts and fine detail may blur "
     "when the radius is large"),
    ("curvature", "Curvature",
     "Smaller balls where the surface bends, larger ones where it is flat"),
    ("learned", "Learned",
     "A small network picks the ball size for each spot from the points around it: smaller "
     "where the scan looks clean, larger where it looks noisy or sparse"),
)

OUTLIER_ITEMS = (
    ("auto", "Auto", "Drop stray points when they are at least 1 % of the cloud (a scan with "
                     "strays); keep a cleaner cloud as it is"),
    ("drop", "Drop", "Always drop points isolated from the surface"),
    ("keep", "Keep", "Use every point"),
)

DEVICE_ITEMS = (
    ("auto", "Auto", "Use the graphics card when PyTorch with CUDA is installed, else the CPU"),
    ("cpu", "CPU", "Always compute on the processor"),
    ("cuda", "CUDA", "Compute on an NVIDIA graphics card (needs PyTorch with CUDA and a GPU)"),
)


def available_radius_modes() -> set:
    """The radius modes the engine has built; all of them when the engine cannot be asked."""
    try:
        from ..engine import radius
    except ImportError:
        return {mode for mode, _, _ in RADIUS_MODE_ITEMS}
    return set(radius.POLICIES)


def _rho_min_changed(self, context):
    # Keep rho_min <= rho_max while the user drags either end of the range.
    if self.rho_min > self.rho_max:
        self.rho_max = self.rho_min


def _rho_max_changed(self, context):
    if self.rho_max < self.rho_min:
        self.rho_min = self.rho_max


class UDFR_SceneSettings(bpy.types.PropertyGroup):
    """How the Reconstruct button rebuilds a surface from the active point cloud."""

    radius_mode: EnumProperty(
        name="Radius Mode",
        description="How big a neighbourhood of points is used to judge the distance to the "
                    "surface at each spot",
        items=RADIUS_MODE_ITEMS,
        default=_DEFAULTS.radius_mode,
    )
    radius: FloatProperty(
        name="Radius",
        description="Neighbourhood size as a fraction of the cloud's longest side. Larger "
                    "fills holes and smooths noise; smaller keeps thin parts and detail",
        default=_DEFAULTS.radius, min=0.001, max=0.2, soft_min=0.005, soft_max=0.06,
        step=0.1, precision=3,
    )
    parent_radius: FloatProperty(
        name="Largest Radius",
        description="The biggest neighbourhood any spot may use, as a fraction of the cloud's "
                    "longest side. Each spot gets a radius between Range Min and Max times this. "
                    "Larger fills holes and smooths noise; smaller keeps thin parts and detail",
        default=_DEFAULTS.parent_radius, min=0.001, max=0.2, soft_min=0.005, soft_max=0.06,
        step=0.1, precision=3,
    )
    rho_min: FloatProperty(
        name="Min",
        description="Smallest radius a spot may get, as a share of the Largest Radius",
        default=_DEFAULTS.rho_min, min=0.05, max=1.0, step=1, precision=2,
        subtype='FACTOR', update=_rho_min_changed,
    )
    rho_max: FloatProperty(
        name="Max",
        description="Biggest radius a spot may get, as a share of the Largest Radius",
        default=_DEFAULTS.rho_max, min=0.05, max=1.0, step=1, precision=2,
        subtype='FACTOR', update=_rho_max_changed,
    )
    resolution: IntProperty(
        name="Resolution",
        description="Grid cells along the cloud's longest side. Higher keeps finer detail but "
                    "takes longer and uses more memory (about 8x per doubling)",
        default=_DEFAULTS.resolution, min=32, max=1024, soft_min=64, soft_max=512,
    )
    device: EnumProperty(
        name="Device",
        description="Where the neural network runs",
        items=DEVICE_ITEMS,
        default=_DEFAULTS.device,
    )
    seed: IntProperty(
        name="Seed",
        description="Same cloud, same settings and same seed give the same mesh",
        default=_DEFAULTS.seed, min=0,
    )
    min_component_faces: IntProperty(
        name="Min Piece Faces",
        description="Delete loose pieces of the result with fewer faces than this "
                    "(0 keeps every piece)",
        default=_DEFAULTS.min_component_faces, min=0, soft_max=10000,
    )
    outliers: EnumProperty(
        name="Outliers",
        description="What to do with stray points floating off the surface",
        items=OUTLIER_ITEMS,
        default=_DEFAULTS.outliers,
    )
    hide_source: BoolProperty(
        name="Hide Cloud",
        description="Hide the point cloud once its mesh is made, so the mesh can be seen (the "
                    "eye icon in the Outliner shows it again)",
        default=True,
    )
    outlier_ratio: FloatProperty(
        name="Outlier Ratio",
        description="A point is stray when its gap to its neighbours is more than this many "
                    "times that of the points around it (lower finds more)",
        default=_DEFAULTS.outlier_ratio, min=1.5, max=20.0, step=10, precision=1,
    )


def to_settings(props: UDFR_SceneSettings) -> ReconstructSettings:
    """The engine's settings for the scene's panel values (validated)."""
    # Blender stores floats in single precision: round so 0.018 reaches the engine as 0.018.
    return ReconstructSettings(
        radius_mode=props.radius_mode,
        radius=round(props.radius, 6),
        parent_radius=round(props.parent_radius, 6),
        rho_min=round(props.rho_min, 6),
        rho_max=round(props.rho_max, 6),
        resolution=props.resolution,
        device=props.device,
        seed=props.seed,
        min_component_faces=props.min_component_faces,
        outliers=props.outliers,
        outlier_ratio=round(props.outlier_ratio, 6),
    ).validate()


def scene_settings(scene) -> UDFR_SceneSettings:
    """The scene's panel settings (registered by the package's ``register()``)."""
    return scene.udf_reconstruction


CLASSES = (UDFR_SceneSettings,)
