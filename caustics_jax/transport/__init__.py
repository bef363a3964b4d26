"""Light transport along refracted paths: the D factor (seed 001 eq. 25-33), caustic
irradiance, brute-force photon tracing and photon differentials (seeds 003, 004), visibility of a
path through the surface (seed 001 §4) and the SMS estimators seed 001 §5 compares against."""

from .contribution import irradiance, path_irradiance
from .differentials import autodiff_D, ray_differential_D
from .estimators import EstimatorResult, sms_biased, sms_unbiased, surface_starts
from .photon_differentials import (
    compression_ratio,
    compression_ratio_exact,
    footprint_ellipse,
    photon_differential_irradiance,
    splat_footprints,
    texel_jacobian,
    triangle_area,
)
from .photons import (
    EmissionPlane,
    PhotonHits,
    PhotonMap,
    ReceiverGrid,
    photon_irradiance,
    surface_hits,
    trace_photons,
)
from .visibility import path_visible

__all__ = [
    "EmissionPlane",
    "PhotonHits",
    "EstimatorResult",
    "PhotonMap",
    "ReceiverGrid",
    "autodiff_D",
    "compression_ratio",
    "compression_ratio_exact",
    "footprint_ellipse",
    "irradiance",
    "path_irradiance",
    "path_visible",
    "photon_differential_irradiance",
    "photon_irradiance",
    "ray_differential_D",
    "sms_biased",
    "sms_unbiased",
    "splat_footprints",
    "surface_hits",
    "trace_photons",
    "surface_starts",
    "texel_jacobian",
    "triangle_area",
]
