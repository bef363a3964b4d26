"""caustics_jax: a JAX testbed for the mathematics of interactive caustics.

The public API is what this module re-exports (`__all__`): the solvers and their
options, irradiance and photons, meshes and scenes, and the pure kernels. The modules
`kernels`, `scenes`, `export` and `testing` are reachable as attributes (`cj.export` is
imported on first use). float64 is never switched on by importing the package: use
`precision("float64")` or `enable_x64()`. The sub-packages are the layers of
docs/map.md "Layers and import graph".
"""

import importlib

from . import kernels, scenes
from ._version import __version__
from .accel.prepared import PreparedSurface, prepare, start_points
from .math.barycentric import barycentric_point, edge_barycentric, interpolated_normal
from .math.conic import (
    conic_coefficients,
    conic_tangent,
    conic_value,
    edge_intersections,
    solve_quadratic,
    tangent_to_world,
)
from .math.geometry import fresnel_reflectance, fresnel_transmittance, reflect, refract, safe_normalize
from .math.objectives import (
    ObjectiveStatus,
    angle_difference_residual,
    half_vector_residual,
    signed_sine,
    signed_sine_and_status,
)
from .runtime.precision import enable_x64, precision
from .solvers import Exhaustive, ExhaustiveSolution, Newton, Solution, Status, Trace, Walk, solve
from .surface.features import SceneFeatures, features
from .surface.lights import Directional
from .surface.mesh import SurfaceMesh, cross_edge
from .transport import (
    ReceiverGrid,
    autodiff_D,
    compression_ratio,
    compression_ratio_exact,
    footprint_ellipse,
    irradiance,
    path_irradiance,
    photon_differential_irradiance,
    photon_irradiance,
    ray_differential_D,
    sms_biased,
    sms_unbiased,
    texel_jacobian,
)

__all__ = [
    "__version__",
    "angle_difference_residual",
    "autodiff_D",
    "barycentric_point",
    "compression_ratio",
    "compression_ratio_exact",
    "conic_coefficients",
    "conic_tangent",
    "conic_value",
    "cross_edge",
    "Directional",
    "edge_barycentric",
    "edge_intersections",
    "enable_x64",
    "Exhaustive",
    "ExhaustiveSolution",
    "export",
    "features",
    "footprint_ellipse",
    "fresnel_reflectance",
    "fresnel_transmittance",
    "half_vector_residual",
    "interpolated_normal",
    "irradiance",
    "kernels",
    "Newton",
    "ObjectiveStatus",
    "path_irradiance",
    "photon_differential_irradiance",
    "photon_irradiance",
    "precision",
    "prepare",
    "PreparedSurface",
    "ray_differential_D",
    "ReceiverGrid",
    "reflect",
    "refract",
    "safe_normalize",
    "SceneFeatures",
    "scenes",
    "signed_sine",
    "signed_sine_and_status",
    "sms_biased",
    "sms_unbiased",
    "Solution",
    "solve",
    "solve_quadratic",
    "start_points",
    "Status",
    "SurfaceMesh",
    "tangent_to_world",
    "testing",
    "texel_jacobian",
    "Trace",
    "Walk",
]

#: Sub-packages imported on first attribute access: they pull in the exporter and the
#: oracle, which `import caustics_jax` does not need.
_LAZY = ("export", "shaders", "testing")


def __getattr__(name: str):
    if name in _LAZY:
        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
