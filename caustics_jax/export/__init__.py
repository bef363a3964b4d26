"""Reference data for shader tests (DESIGN.md "Reference data for shader tests"; docs/export.md).

`export(out_dir)` writes, per kernel, `<kernel>.json` (the manifest) and `<kernel>.bin`
(little-endian std430 records), plus `caustics_records.h`, a C header with one struct
per record. Every record holds the kernel's inputs, rounded to float32, its outputs, the
float64 reference computed *from those rounded inputs* by the package's own kernel and
then rounded to float32, and a case tag (`random`, `planted`, `adversarial`).

One concept per module:

- `records`: the std430 record format (`Field`, `layout`, `pack_records`, `read_records`,
  `load`, `c_header`, `CASES`, `FORMAT_VERSION`); numpy only.
- `registry`: `Kernel`, `KERNELS` and `register`, the one call that declares a kernel.
- `tolerance`: the float32 audit (package data `float32_audit.json`), tolerance
  derivation and `compare`, `ulp_distance`, `field_scale`; numpy only.
- `cases`: building blocks of the case generators (`f64` runs a package kernel in float64).
- `cases_optics`, `cases_conic`, `cases_paths`, `cases_screen`: each kernel's generator,
  conditioning filter and registration, side by side.
- `cases_mesh`, `cases_photons`, `cases_collection`, `cases_culling`: the pipeline kernels added for the
  Vulkan backend (edge crossing; cascade dispatch, photon intensity, sprite; resolve and
  EMA, reuse acceptance, denoiser sub-pass).
- `writer`: `export_kernel` and `export`.

Whole scenes, next to the kernels (docs/export.md "Scenes"):

- `scene_records`: the seven std430 buffers of a scene file (`BUFFERS`, `pack_scene`,
  `read_scene`, `load_scene`, `scene_c_header`); numpy only.
- `scene_registry`: `SceneSpec`, `SceneData`, `SCENES` and `register_scene`.
- `scene_cases`: the exported scenes (pools, lagoon, jittered mesh, lanes crossing no
  surface, stress categories).
- `scene_writer`: `export_scene` (the float32 walk's or one-step Newton's expected lanes,
  the float64 reference, tolerances), `scene_stem` and `write_scenes`.
"""

# isort: off
# The import order of the case modules is the registration order, which is the order of
# the manifests, of the structs in caustics_records.h and of the CLI's default kernels.
from . import cases_optics  # refract, fresnel
from . import cases_conic  # conic_coefficients, conic_tangent, edge_intersections
from . import cases_paths  # signed_sine, d_factor, photon_compression
from . import cases_screen  # reuse_weight, bilateral_weight, fixed_point
from . import cases_mesh  # cross_edge
from . import cases_photons  # cascade_dispatch, photon_intensity, sprite
from . import cases_collection  # resolve_ema, reuse_accepted, denoise_subpass
from . import cases_culling  # photon_cull, throughput_cull
from . import scene_cases  # the scenes (scene_registry.SCENES)
# isort: on
from .cases_conic import EDGE_TOL
from .cases_screen import FIXED_POINT_ADDENDS
from .records import (
    CASES,
    FORMAT_VERSION,
    Field,
    c_header,
    c_struct,
    layout,
    load,
    pack_records,
    read_records,
    record_fields,
)
from .registry import KERNELS, Kernel, register
from .scene_cases import mesh_file_scene, scene_name
from .scene_records import BUFFER_ALIGNMENT, BUFFERS, load_scene, pack_scene, read_scene, scene_c_header
from .scene_registry import SCENES, SceneData, SceneSpec, register_scene
from .scene_writer import NEWTON, export_scene, scene_stem, write_scenes
from .tolerance import (
    AUDIT_FILE,
    F64_BUDGET,
    SAFETY,
    STORAGE_ROUNDING,
    compare,
    derive_tolerance,
    field_scale,
    load_audit,
    ulp_distance,
)
from .writer import export, export_kernel

__all__ = [
    "AUDIT_FILE",
    "BUFFERS",
    "BUFFER_ALIGNMENT",
    "CASES",
    "EDGE_TOL",
    "F64_BUDGET",
    "FIXED_POINT_ADDENDS",
    "FORMAT_VERSION",
    "Field",
    "KERNELS",
    "Kernel",
    "SAFETY",
    "SCENES",
    "STORAGE_ROUNDING",
    "SceneData",
    "SceneSpec",
    "c_header",
    "c_struct",
    "cases_collection",
    "cases_conic",
    "cases_culling",
    "cases_mesh",
    "cases_optics",
    "cases_paths",
    "cases_photons",
    "cases_screen",
    "compare",
    "derive_tolerance",
    "export",
    "export_kernel",
    "export_scene",
    "field_scale",
    "layout",
    "load",
    "load_audit",
    "load_scene",
    "mesh_file_scene",
    "NEWTON",
    "pack_records",
    "pack_scene",
    "read_records",
    "read_scene",
    "record_fields",
    "register",
    "register_scene",
    "scene_c_header",
    "scene_cases",
    "scene_name",
    "scene_stem",
    "ulp_distance",
    "write_scenes",
]
