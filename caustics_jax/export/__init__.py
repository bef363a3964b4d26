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
- `writer`: `export_kernel` and `export`.
"""

# isort: off
# The import order of the case modules is the registration order, which is the order of
# the manifests, of the structs in caustics_records.h and of the CLI's default kernels.
from . import cases_optics  # refract, fresnel
from . import cases_conic  # conic_coefficients, conic_tangent, edge_intersections
from . import cases_paths  # signed_sine, d_factor, photon_compression
from . import cases_screen  # reuse_weight, bilateral_weight, fixed_point
# isort: on
from .cases_conic import EDGE_TOL
from .cases_screen import FIXED_POINT_ADDENDS
from .records import CASES, FORMAT_VERSION, Field, c_header, layout, load, pack_records, read_records, record_fields
from .registry import KERNELS, Kernel, register
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
    "CASES",
    "EDGE_TOL",
    "F64_BUDGET",
    "FIXED_POINT_ADDENDS",
    "FORMAT_VERSION",
    "KERNELS",
    "SAFETY",
    "STORAGE_ROUNDING",
    "Field",
    "Kernel",
    "c_header",
    "cases_conic",
    "cases_optics",
    "cases_paths",
    "cases_screen",
    "compare",
    "derive_tolerance",
    "export",
    "export_kernel",
    "field_scale",
    "layout",
    "load",
    "load_audit",
    "pack_records",
    "read_records",
    "record_fields",
    "register",
    "ulp_distance",
]
