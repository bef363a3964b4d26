"""caustics_jax: a JAX testbed for the mathematics of interactive caustics.

The public API is what this module re-exports. float64 is never switched on by importing
the package: use `precision("float64")` or `enable_x64()`.
"""

from . import kernels, scenes
from ._precision import enable_x64, precision
from ._version import __version__
from .barycentric import barycentric_point, edge_barycentric, interpolated_normal
from .conic import (
    conic_coefficients,
    conic_tangent,
    conic_value,
    edge_intersections,
    solve_quadratic,
    tangent_to_world,
)
from .features import SceneFeatures, features
from .geometry import (
    fresnel_reflectance,
    fresnel_transmittance,
    reflect,
    refract,
    safe_normalize,
)
from .mesh import SurfaceMesh, cross_edge
from .objectives import (
    ObjectiveStatus,
    angle_difference_residual,
    half_vector_residual,
    signed_sine,
    signed_sine_and_status,
)
from .prepared import PreparedSurface, prepare, start_points
from .solvers import Exhaustive, ExhaustiveSolution, Newton, Solution, Status, Trace, Walk, solve
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
    "Exhaustive",
    "ExhaustiveSolution",
    "Newton",
    "PreparedSurface",
    "Trace",
    "sms_biased",
    "sms_unbiased",
    "Walk",
    "__version__",
    "kernels",
    "prepare",
    "ReceiverGrid",
    "SceneFeatures",
    "Solution",
    "Status",
    "SurfaceMesh",
    "cross_edge",
    "scenes",
    "solve",
    "start_points",
    "ObjectiveStatus",
    "angle_difference_residual",
    "autodiff_D",
    "barycentric_point",
    "compression_ratio",
    "compression_ratio_exact",
    "footprint_ellipse",
    "conic_coefficients",
    "conic_tangent",
    "conic_value",
    "edge_barycentric",
    "edge_intersections",
    "enable_x64",
    "features",
    "fresnel_reflectance",
    "fresnel_transmittance",
    "half_vector_residual",
    "interpolated_normal",
    "irradiance",
    "path_irradiance",
    "photon_differential_irradiance",
    "photon_irradiance",
    "precision",
    "ray_differential_D",
    "reflect",
    "refract",
    "safe_normalize",
    "signed_sine",
    "signed_sine_and_status",
    "solve_quadratic",
    "tangent_to_world",
    "texel_jacobian",
]
