"""GLSL 450 ports of the exported kernels and of the solver (package data), and their Vulkan
conformance harness (docs/export.md).

`<kernel>.glsl` holds one kernel's `cj_run(inout Record r)`; `common.glsl` every formula
several ports share; `scene_mesh.glsl`, `start_point.glsl`, `arcs.glsl`, `walk.glsl` and
`scene_lane.glsl` the start point, the curve walk, D and the irradiance of a scene's lanes;
`host.c` a minimal Vulkan compute host. `vulkan.py` builds and runs them;
`conformance.py` judges the kernels against the data of `caustics-jax export`,
`scene_conformance.py` the scenes.
"""
