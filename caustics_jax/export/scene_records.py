"""The std430 buffers of a scene file (DESIGN.md "Reference data for shader tests";
docs/export.md "Scenes").

A scene file (`<scene>.bin` for the walk, `<scene>.newton.bin` for the one-step Newton)
holds seven buffers back to back, each starting on a multiple of `BUFFER_ALIGNMENT` bytes
(Vulkan's largest `minStorageBufferOffsetAlignment`, so one upload can be bound at every
buffer's offset): `scene` (one record: counts, the grid description, the face cells, the
solver and its options), `vertices`, `faces` (vertex indices, neighbours and entry edges:
the adjacency a solver crosses edges with), `lanes` (inputs, the float32 solver's
expected results, the float64 reference), and the start points' face cells
(`accel.face_cells.FaceCells`, the structure the testbed's start points traverse):
`cell_lines` (the `nu + 1` lines along axis `cell_axis_u`, then the `nv + 1` along
`cell_axis_v`), `cell_faces` (the cell table's rows of `cell_width` faces, flat, -1
padding) and `cell_rows` (per row: the row continuing its list, -1 where it ends, and its
cell's height range along `cell_axis_w`). The manifest `<scene>.json` lists each buffer's
offset, count, stride and fields exactly like a kernel manifest lists its record
(`records.record_fields`), and `caustics_scene.h` declares the structs in C.

This module is the layout and nothing else (numpy only), built on `records.py`.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .records import (
    CASE_FIELD,
    FORMAT_VERSION,
    Field,
    c_struct,
    layout,
    pack_records,
    read_records,
    record_fields,
)

#: Byte alignment of each buffer within a scene file.
BUFFER_ALIGNMENT = 256
#: Codes of the walk's bracket option in the `scene` record.
BRACKETS = {"illinois": 0, "bisection": 1}
#: Codes of the `solver` member of the `scene` record (and the manifest's `solver`).
SOLVERS = {"walk": 0, "newton": 1}
#: Codes of the `cell_kind` member: the exact cells of a heightfield grid, or binned faces.
CELL_KINDS = {"grid": 0, "bins": 1}


def _fields(spec: dict[str, str], role: str) -> list[Field]:
    return [Field.parse(n, t, role) for n, t in spec.items()]


#: One record: sizes, the regular heightfield grid (`has_grid = 0` for a general mesh: the
#: grid members are then 0; descriptive, the start points use the cells), the vertex
#: height range, the face cells (`cell_nu x cell_nv` cells over world axes `cell_axis_u`,
#: `cell_axis_v`, projected along `cell_axis_w`, whose vertex coordinates span `cell_w_lo`
#: to `cell_w_hi`; `cell_rows` rows of `cell_width` faces; kind `CELL_KINDS`), the solver
#: (`SOLVERS`) and its options: the walk's `tol`, `max_steps`, `bracket`,
#: `ellipse_samples`; the Newton's `tol`, `max_steps` (its iteration cap, `max_patches`) and
#: `initial_step` (the first step size beta). `grid_x1 = x0 + nx dx` and `grid_y1` are
#: rounded once from float64, as the testbed rounds them.
SCENE_FIELDS = _fields({
    "n_vertices": "uint", "n_faces": "uint", "n_lanes": "uint", "has_grid": "uint",
    "grid_nx": "int", "grid_ny": "int", "grid_x0": "float", "grid_y0": "float",
    "grid_dx": "float", "grid_dy": "float", "grid_x1": "float", "grid_y1": "float",
    "z_min": "float", "z_max": "float", "tol": "float", "max_steps": "uint",
    "bracket": "uint", "ellipse_samples": "uint",
    "cell_nu": "uint", "cell_nv": "uint", "cell_width": "uint", "cell_rows": "uint", "cell_kind": "uint",
    "cell_axis_u": "uint", "cell_axis_v": "uint", "cell_axis_w": "uint", "cell_w_lo": "float", "cell_w_hi": "float",
    "solver": "uint", "initial_step": "float",
}, "scene")

#: The face cells of the start points (module docstring): grid lines, the flat cell table,
#: and per row its continuation and the height range of its cell's faces (empty cells:
#: `z_lo` = float32 max, `z_hi` = -float32 max, so no segment meets them).
CELL_LINE_FIELDS = _fields({"x": "float"}, "scene")
CELL_FACE_FIELDS = _fields({"face": "int"}, "scene")
CELL_ROW_FIELDS = _fields({"more": "int", "z_lo": "float", "z_hi": "float"}, "scene")

#: Per vertex: position and unit vertex normal (outward, toward the light).
VERTEX_FIELDS = _fields({"position": "vec3", "normal": "vec3"}, "scene")

#: Per face: vertex indices (counter-clockwise seen from outside), the face across edge k
#: (vertices k, k+1 mod 3; -1 on a boundary) and which edge of that neighbour it is.
FACE_FIELDS = _fields({"v": "uint[3]", "neighbor": "int[3]", "neighbor_edge": "int[3]"}, "scene")

#: Per lane: inputs; the float32 walk's results a port must reproduce (role `output`); the
#: float64 reference and the judging data (role `reference`: `M_ref` + `M_ref_lo` = the
#: float64 point to about 48 bits, as hi and lo float32 parts; `M_tol`; `D_err`, `E_err`: the
#: testbed's float32 error of D and E near the lane's point; `conditioned` = 1 where float32
#: decides the lane's status, `scene_writer`); `case_tag`.
LANE_INPUTS = {"P": "vec3", "L": "vec3", "receiver_normal": "vec3", "eta": "float", "intensity": "float",
               "sigma_t": "float"}
LANE_OUTPUTS = {"start_face": "int", "start_ab": "vec2", "start_found": "uint", "face": "int", "ab": "vec2",
                "M": "vec3", "status": "uint", "crossed": "uint", "iterations": "uint", "residual": "float",
                "D": "float", "D_valid": "uint", "E": "float"}
LANE_REFERENCE = {"M_ref": "vec3", "M_ref_lo": "vec3", "face_ref": "int", "ab_ref": "vec2", "status_ref": "uint",
                  "angle_error": "float", "M_tol": "float", "D_err": "float", "E_err": "float", "conditioned": "uint"}
LANE_FIELDS = (_fields(LANE_INPUTS, "input") + _fields(LANE_OUTPUTS, "output")
               + _fields(LANE_REFERENCE, "reference") + [CASE_FIELD])

#: Buffer name -> fields, in file order (the shader's bindings: `lanes` at 0 in and 1 out,
#: the others from 2 in this order).
BUFFERS: dict[str, list[Field]] = {"scene": SCENE_FIELDS, "vertices": VERTEX_FIELDS, "faces": FACE_FIELDS,
                                   "lanes": LANE_FIELDS, "cell_lines": CELL_LINE_FIELDS,
                                   "cell_faces": CELL_FACE_FIELDS, "cell_rows": CELL_ROW_FIELDS}
#: C struct name of each buffer's record.
C_NAMES = {"scene": "cj_scene_params", "vertices": "cj_scene_vertex", "faces": "cj_scene_face",
           "lanes": "cj_scene_lane", "cell_lines": "cj_scene_cell_line", "cell_faces": "cj_scene_cell_face",
           "cell_rows": "cj_scene_cell_row"}
_C_COMMENTS = {
    "scene": "one record: counts, grid description (has_grid), z range, walk options (tol, max_steps, "
             "bracket 0 illinois / 1 bisection, ellipse_samples)",
    "vertices": "position and unit outward normal per vertex (seed 001 eq. 3, 6-8)",
    "faces": "vertex indices, neighbour across edge k (vertices k, k+1 mod 3; -1 boundary) and its edge index",
    "lanes": "inputs P, L, receiver_normal, eta, intensity, sigma_t; float32 solver results (output); "
             "float64 reference (reference: M_ref + M_ref_lo); case_tag",
    "cell_lines": "face cells: the cell_nu + 1 lines along cell_axis_u, then the cell_nv + 1 along cell_axis_v",
    "cell_faces": "face cells: row r lists faces [r cell_width, (r + 1) cell_width), -1 padding; cell (i, j) "
                  "starts at row j cell_nu + i",
    "cell_rows": "face cells: the row continuing each row's list (-1: none) and its cell's face height range",
}


def pack_scene(values: dict[str, dict[str, np.ndarray]]) -> tuple[dict, bytes]:
    """`(buffers manifest entry, bytes)` of a scene file from one dict of field arrays per buffer
    (leading axis = records; `case_tag` is only in `lanes`)."""
    out, entries, offset = [], {}, 0
    for name, fields in BUFFERS.items():
        vals = dict(values[name])
        count = len(next(iter(vals.values())))
        if "case_tag" not in vals:  # pack_records counts records by case_tag
            vals["case_tag"] = np.zeros(count, np.uint32)
        raw = pack_records(fields, vals)
        _, stride = layout(fields)
        offset = -(-offset // BUFFER_ALIGNMENT) * BUFFER_ALIGNMENT
        pad = offset - sum(len(b) for b in out)
        out.append(b"\0" * pad + raw)
        entries[name] = {"offset": offset, "count": count, "stride": stride, "struct": C_NAMES[name],
                         "fields": record_fields(fields)}
        offset += len(raw)
    return entries, b"".join(out)


def read_scene(manifest: dict, raw: bytes) -> dict[str, dict[str, np.ndarray]]:
    """Every buffer of a scene file as `{buffer: {field: array}}`, from the manifest alone
    (a malformed manifest is a `ValueError`, as in `records.read_records`)."""
    out = {}
    try:
        for name, e in manifest["buffers"].items():
            size = e["count"] * e["stride"]
            if e["offset"] + size > len(raw):
                raise ValueError(f"scene buffer {name} runs past the end of the file ({len(raw)} bytes)")
            out[name] = read_records(e, raw[e["offset"]: e["offset"] + size])
    except (KeyError, TypeError, IndexError, AttributeError) as exc:
        raise ValueError(f"malformed scene manifest (docs/export.md lists its entries): {type(exc).__name__}: "
                         f"{exc}") from None
    return out


def load_scene(out_dir, scene: str) -> tuple[dict, dict[str, dict[str, np.ndarray]]]:
    """`(manifest, buffers)` of `out_dir/<scene>.json` and `.bin`."""
    out_dir = Path(out_dir)
    manifest = json.loads((out_dir / f"{scene}.json").read_text())
    return manifest, read_scene(manifest, (out_dir / f"{scene}.bin").read_bytes())


def scene_c_header() -> str:
    """`caustics_scene.h`: the C11 structs of the four scene buffers, with static asserts."""
    lines = ["/* Generated by `caustics-jax export`: std430 buffers of the caustics_jax scene files.",
             f" * <scene>.bin holds the buffers {', '.join(BUFFERS)}, each at a multiple of "
             f"{BUFFER_ALIGNMENT} bytes;",
             " * <scene>.json gives each buffer's offset, count and stride. vec3 members take 4 floats. */",
             "#ifndef CAUSTICS_SCENE_H", "#define CAUSTICS_SCENE_H", "#include <stddef.h>", "#include <stdint.h>",
             f"#define CAUSTICS_SCENE_VERSION {FORMAT_VERSION}", f"#define CAUSTICS_SCENE_ALIGNMENT {BUFFER_ALIGNMENT}",
             ""]
    for name, fields in BUFFERS.items():
        lines += c_struct(C_NAMES[name], name, _C_COMMENTS[name], fields)
    lines.append("#endif")
    return "\n".join(lines) + "\n"
