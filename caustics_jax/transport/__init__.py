"""Light transport along refracted paths: the D factor (seed 001 eq. 25-33), caustic
irradiance, brute-force photon tracing and photon differentials (seeds 003, 004)."""

from .contribution import irradiance, path_irradiance
from .differentials import autodiff_D, ray_differential_D
from .photon_differentials import (
    compression_ratio,
    compression_ratio_exact,
    footprint_ellipse,
    photon_differential_irradiance,
    splat_footprints,
    texel_jacobian,
    triangle_area,
)
from .photons import EmissionPlane, PhotonMap, ReceiverGrid, photon_irradiance, surface_hits

__all__ = [
    "EmissionPlane",
    "PhotonMap",
    "ReceiverGrid",
    "autodiff_D",
    "compression_ratio",
    "compression_ratio_exact",
    "footprint_ellipse",
    "irradiance",
    "path_irradiance",
    "photon_differential_irradiance",
    "photon_irradiance",
    "ray_differential_D",
    "splat_footprints",
    "surface_hits",
    "texel_jacobian",
    "triangle_area",
]
