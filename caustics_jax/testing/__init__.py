"""What tests and experiments share: the numpy float64 oracle, planted paths, checks.

- `oracle`: MATH.md transcribed once in numpy float64, independent of the JAX kernels
  (`refract`, eq. 3, the shading normal, Fresnel, the refraction-angle error, ...).
- `planted`: random triangles and refracted paths with a known solution, seeded.
- `checks`: `assert_solution_sane`, the checks every solver test runs, and
  `assert_same_lanes` for two schedules of the same lanes.
- `jittered_wave`: `jittered_heightfield`, issue 16's surface.
"""

from . import oracle as oracle
from .checks import assert_same_lanes as assert_same_lanes
from .checks import assert_solution_sane as assert_solution_sane
from .checks import lane_ulps as lane_ulps
from .jittered_wave import jittered_heightfield as jittered_heightfield
from .oracle import NumpyMesh as NumpyMesh
from .oracle import flat_interface_irradiance as flat_interface_irradiance
from .oracle import refraction_angle_error as refraction_angle_error
from .planted import PlantedMeshPaths as PlantedMeshPaths
from .planted import PlantedPath as PlantedPath
from .planted import partly_covered_floor as partly_covered_floor
from .planted import path_endpoints as path_endpoints
from .planted import planted_mesh_paths as planted_mesh_paths
from .planted import planted_paths as planted_paths
from .planted import random_triangles as random_triangles

__all__ = [
    "NumpyMesh",
    "PlantedMeshPaths",
    "PlantedPath",
    "assert_same_lanes",
    "assert_solution_sane",
    "flat_interface_irradiance",
    "jittered_heightfield",
    "lane_ulps",
    "oracle",
    "partly_covered_floor",
    "path_endpoints",
    "planted_mesh_paths",
    "planted_paths",
    "random_triangles",
    "refraction_angle_error",
]
