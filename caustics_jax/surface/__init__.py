"""The surface layer: the refracting mesh and the scenes built on it.

- `mesh`: `SurfaceMesh`, its adjacency and edge crossing;
- `grid`: the regular heightfield grid layout;
- `frames`: per-face local origins (float32 precision for offset meshes);
- `features`: static scene features (what a scene lets the solvers skip);
- `scenes`: scene generators (pools, lagoon) with lights and receivers.
"""
