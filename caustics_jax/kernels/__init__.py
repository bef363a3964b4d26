"""Real-time pipeline kernels (math.md §8, §7 sprites): collection points and fixed point
(seed 000), denoiser, cascades, attenuation, Fresnel and sprites (seed 004), projected
photons (seed 002), energy culling and the adaptive photon budget (seed 003).

Pure, vectorised over leading batch axes, float32 in -> float32 out.
"""

from .attenuation import (
    fresnel_reflect_approx,
    fresnel_refract_approx,
    intensity_attenuation,
    ray_intensity,
    schlick_f0,
)
from .bilateral import (
    C_SCENE_FACTOR,
    C_SCENE_FACTOR_ALG4,
    adaptive_kernel_params,
    bilateral_denoise,
    bilateral_weight,
    denoise_subpass,
    luminance,
)
from .budget import BUDGET_FLOOR, photon_budget
from .cascades import (
    cascade_deltas,
    cascade_dispatch,
    cascade_intensity_scale,
    cascade_projection,
    cascade_thread_counts,
    ccm0_size,
    light_position,
)
from .collection import (
    RADIUS_CAP,
    cylinder_aabb,
    gather_previous,
    in_cylinder,
    pixel_footprint_radius,
    pixel_spread_angle,
    ray_cone_propagate,
    ray_cone_radius,
    resolve,
    reuse_accepted,
    reuse_weight,
    temporal_ema,
)
from .culling import CullStatus, energy_cull, photon_cull, throughput, throughput_cull
from .fixed_point import FixedPointSum, fixed_point_accumulate, fixed_point_decode, fixed_point_encode
from .projection import projected_photon_position, ray_plane_intersection
from .sprites import sprite_basis, sprite_corners, sprite_foreshortening, sprite_intensity, sprite_size

__all__ = [
    "BUDGET_FLOOR",
    "C_SCENE_FACTOR",
    "C_SCENE_FACTOR_ALG4",
    "CullStatus",
    "FixedPointSum",
    "RADIUS_CAP",
    "adaptive_kernel_params",
    "bilateral_denoise",
    "bilateral_weight",
    "cascade_deltas",
    "cascade_dispatch",
    "cascade_intensity_scale",
    "cascade_projection",
    "cascade_thread_counts",
    "ccm0_size",
    "cylinder_aabb",
    "denoise_subpass",
    "energy_cull",
    "fixed_point_accumulate",
    "fixed_point_decode",
    "fixed_point_encode",
    "fresnel_reflect_approx",
    "fresnel_refract_approx",
    "gather_previous",
    "in_cylinder",
    "intensity_attenuation",
    "light_position",
    "luminance",
    "photon_budget",
    "photon_cull",
    "pixel_footprint_radius",
    "pixel_spread_angle",
    "projected_photon_position",
    "ray_cone_propagate",
    "ray_cone_radius",
    "ray_intensity",
    "ray_plane_intersection",
    "resolve",
    "reuse_accepted",
    "reuse_weight",
    "schlick_f0",
    "sprite_basis",
    "sprite_corners",
    "sprite_foreshortening",
    "sprite_intensity",
    "sprite_size",
    "temporal_ema",
    "throughput",
    "throughput_cull",
]
