"""caustics_jax: a JAX testbed for the mathematics of interactive caustics.

The public API is what this module re-exports. float64 is never switched on by importing
the package: use `precision("float64")` or `enable_x64()`.
"""

from ._precision import enable_x64, precision
from .geometry import (
    fresnel_reflectance,
    fresnel_transmittance,
    reflect,
    refract,
    safe_normalize,
)

__version__ = "0.1.0"

__all__ = [
    "enable_x64",
    "fresnel_reflectance",
    "fresnel_transmittance",
    "precision",
    "reflect",
    "refract",
    "safe_normalize",
]
