"""Scene generators, `cj.scenes`: flat and wavy pools and a lagoon, each a `Scene` with its
surface mesh, receivers and lights (docs/mesh.md).

The generators live in the surface layer (`caustics_jax.surface.scenes`); this module is
their public name at the package root, so `cj.scenes.wavy_pool` and
`from caustics_jax.scenes import wavy_pool` both work.
"""

from .surface.scenes import LIGHTS, MAX_TRIANGLES, Lights, Scene, flat_pool, lagoon, wavy_pool

__all__ = ["LIGHTS", "MAX_TRIANGLES", "Lights", "Scene", "flat_pool", "lagoon", "wavy_pool"]
