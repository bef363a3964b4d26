"""What tests and experiments share: the numpy float64 oracle, planted paths, checks.

- `oracle`: math.md transcribed once in numpy float64, independent of the JAX kernels
  (`refract`, eq. 3, the shading normal, Fresnel, the refraction-angle error, ...).
- `planted`: random triangles and refracted paths with a known solution, seeded.
- `checks`: `assert_solution_sane`, the checks every solver test runs, and
  `assert_same_lanes` for two schedules of the same lanes.
- `jittered_wave`: `jittered_heightfield`, the jittered surface of docs/solvers.md "The
  certified reference".
"""

from . import oracle
from .checks import assert_same_lanes, assert_solution_sane, lane_ulps
from .jittered_wave import jittered_heightfield
from .oracle import NumpyMesh, flat_interface_irradiance, refraction_angle_error
from .planted import (
    PlantedMeshPaths,
    PlantedPath,
    partly_covered_floor,
    path_endpoints,
    planted_mesh_paths,
    planted_paths,
    random_triangles,
)

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
