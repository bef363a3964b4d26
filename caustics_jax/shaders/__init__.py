"""GLSL 450 ports of the exported kernels (package data) and their Vulkan conformance harness.

`<kernel>.glsl` holds one kernel's math and `cj_run(inout Record r)`; `common.glsl` the
helpers several share; `host.c` a minimal Vulkan compute host. `conformance.py` assembles
each shader with the record struct of its manifest, compiles it with glslangValidator and
runs it against the data of `caustics-jax export` (docs/export.md).
"""
