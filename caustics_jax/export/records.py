"""The std430 record format of the shader reference data (DESIGN.md "Reference data for shader tests").

A record is a GLSL `struct` in a `buffer` laid out by std430: `float`, `int`, `uint` take
4 bytes; `vec2` 8, aligned to 8; `vec3` 16, aligned to 16 (its fourth float is explicit
padding, so nothing ever packs into it); `vec4` 16; arrays of scalars have stride 4, of
`vec2` 8, of `vec3`/`vec4` 16; the record stride is the struct size rounded up to its
largest alignment. Every record ends with `uint case_tag` (`CASES`).

This module is the format and nothing else (numpy only): `Field` and `layout` give the
offsets, `pack_records` writes records, `read_records` and `load` read them back from the
manifest alone, `c_header` declares them in C (docs/export.md "Format").
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

#: Format version of the manifest and binary layout; bump on any incompatible change.
FORMAT_VERSION = 3
#: Case tags, stored per record in the `case_tag` field (`case` is a keyword in C and GLSL).
CASES = {"random": 0, "planted": 1, "adversarial": 2}

# std430: (base alignment, size) of one element, numpy dtype, C element type, storage
# width (vec3 stored as 4 floats, the fourth padding).
_TYPES = {
    "float": (4, 4, "<f4", "float", 1),
    "int": (4, 4, "<i4", "int32_t", 1),
    "uint": (4, 4, "<u4", "uint32_t", 1),
    "vec2": (8, 8, "<f4", "float", 2),
    "vec3": (16, 16, "<f4", "float", 4),
    "vec4": (16, 16, "<f4", "float", 4),
}
_WIDTH = {"float": 1, "int": 1, "uint": 1, "vec2": 2, "vec3": 3, "vec4": 4}
_NUMPY = {"float32": "f4", "int32": "i4", "uint32": "u4"}


@dataclasses.dataclass(frozen=True)
class Field:
    """One member of a record: GLSL type, optional array length, role (input/output/case)."""

    name: str
    glsl: str
    role: str
    length: int | None = None
    scale_field: str | None = None  # tolerance scale: this field's magnitude instead of own

    @classmethod
    def parse(cls, name: str, decl: str, role: str, scale_field: str | None = None) -> Field:
        """`Field` from a GLSL member type as written in a struct: `"vec3"`, `"vec3[3]"`, `"float[6]"`."""
        glsl, _, length = decl.partition("[")
        if glsl not in _TYPES or (length and not length.rstrip("]").isdigit()):
            raise ValueError(f"field {name}: unsupported GLSL type {decl!r}")
        return cls(name, glsl, role, int(length.rstrip("]")) if length else None, scale_field)

    @property
    def shape(self) -> list[int]:
        w = _WIDTH[self.glsl]
        return ([self.length] if self.length else []) + ([w] if w > 1 else [])

    @property
    def storage_shape(self) -> list[int]:
        w = _TYPES[self.glsl][4]
        return ([self.length] if self.length else []) + ([w] if w > 1 else [])

    @property
    def dtype(self) -> str:
        return {"<f4": "float32", "<i4": "int32", "<u4": "uint32"}[_TYPES[self.glsl][2]]

    @property
    def size(self) -> int:
        return _TYPES[self.glsl][1] * (self.length or 1)


#: The last member of every record.
CASE_FIELD = Field("case_tag", "uint", "case")


def _fields(record) -> list[Field]:
    """The field list of a `Kernel` (anything with `.fields`) or of a plain list of fields."""
    return list(getattr(record, "fields", record))


def layout(fields) -> tuple[list[int], int]:
    """std430 offsets of `fields` (vec3 padded to 16 bytes) and the record stride."""
    offset, align_max, offsets = 0, 4, []
    for f in _fields(fields):
        align = _TYPES[f.glsl][0]
        offset = -(-offset // align) * align
        offsets.append(offset)
        offset += f.size
        align_max = max(align_max, align)
    return offsets, -(-offset // align_max) * align_max


def record_fields(fields) -> list[dict]:
    """Manifest entries of the record's fields (name, dtype, shape, storage_shape, offset, role, glsl)."""
    fields = _fields(fields)
    offsets, _ = layout(fields)
    return [{"name": f.name, "dtype": f.dtype, "shape": f.shape, "storage_shape": f.storage_shape,
             "offset": off, "role": f.role, "glsl": f.glsl + (f"[{f.length}]" if f.length else "")}
            for f, off in zip(fields, offsets, strict=True)]


def pack_records(fields, values: dict[str, np.ndarray]) -> bytes:
    """std430 bytes of `values` (one array per field, leading axis = records); `fields` a `Kernel` or list."""
    fields = _fields(fields)
    offsets, stride = layout(fields)
    count = len(values["case_tag"])
    buf = np.zeros(count * stride, np.uint8)
    for f, off in zip(fields, offsets, strict=True):
        np_dtype = np.dtype(_TYPES[f.glsl][2])
        v = np.asarray(values[f.name]).astype(np_dtype).reshape(count, *f.shape)
        if f.storage_shape != f.shape:
            pad = np.zeros((count, *f.storage_shape), np_dtype)
            pad[..., : f.shape[-1]] = v
            v = pad
        item = np.ascontiguousarray(v).view(np.uint8).reshape(count, -1)
        rows = buf.reshape(count, stride)
        rows[:, off: off + item.shape[1]] = item
    return buf.tobytes()


def _field_view(raw: bytes | np.ndarray, entry: dict, count: int, stride: int) -> np.ndarray:
    """Strided numpy view of one field over all records, padding columns dropped."""
    dtype = np.dtype("<" + _NUMPY[entry["dtype"]])
    sshape = list(entry["storage_shape"])
    strides = [dtype.itemsize] * len(sshape)
    for i in range(len(sshape) - 2, -1, -1):
        strides[i] = strides[i + 1] * sshape[i + 1]
    view = np.ndarray((count, *sshape), dtype, buffer=raw, offset=entry["offset"], strides=(stride, *strides))
    if sshape != list(entry["shape"]):
        view = view[..., : entry["shape"][-1]]
    return np.array(view)


def read_records(manifest: dict, raw: bytes) -> dict[str, np.ndarray]:
    """Every field of a `.bin` as a numpy array `(count, *shape)`, using nothing but the manifest.

    A manifest without the documented entries (docs/export.md), or whose fields do not fit
    the records, is a `ValueError` (a corrupt `fields` had been a `TypeError` inside numpy)."""
    try:
        if len(raw) != manifest["count"] * manifest["stride"]:
            raise ValueError(f"binary holds {len(raw)} bytes, manifest says {manifest['count']} x {manifest['stride']}")
        return {e["name"]: _field_view(raw, e, manifest["count"], manifest["stride"]) for e in manifest["fields"]}
    except (KeyError, TypeError, IndexError, AttributeError) as exc:
        raise ValueError(f"malformed manifest (docs/export.md lists its entries): "
                         f"{type(exc).__name__}: {exc}") from None


def load(out_dir, kernel: str) -> tuple[dict, dict[str, np.ndarray]]:
    """`(manifest, records)` of `out_dir/<kernel>.json` and `.bin`."""
    out_dir = Path(out_dir)
    manifest = json.loads((out_dir / f"{kernel}.json").read_text())
    return manifest, read_records(manifest, (out_dir / f"{kernel}.bin").read_bytes())


def _c_field(f: Field, offset: int) -> str:
    ctype = _TYPES[f.glsl][3]
    dims = "".join(f"[{d}]" for d in f.storage_shape)
    note = "  /* vec3: 4th float is padding */" if f.glsl == "vec3" else ""
    return f"    {ctype} {f.name}{dims}; /* offset {offset}, {f.role} */{note}"


def c_header(kernels) -> str:
    """C11 header declaring one struct per record (each kernel: `name`, `equations`, `fields`),
    with static asserts on every offset and size. A kernel given twice is declared once
    (a second typedef of the struct would not compile)."""
    unique: dict = {}
    for k in kernels:
        unique.setdefault(k.name, k)
    lines = ["/* Generated by `caustics-jax export`: std430 records of the caustics_jax reference data.",
             " * One struct per kernel; arrays of vec3 and vec3 members take 4 floats (the 4th is padding).",
             " * Case tags: " + ", ".join(f"{k} = {v}" for k, v in CASES.items()) + ". */",
             "#ifndef CAUSTICS_RECORDS_H", "#define CAUSTICS_RECORDS_H", "#include <stddef.h>",
             "#include <stdint.h>", f"#define CAUSTICS_RECORDS_VERSION {FORMAT_VERSION}", ""]
    for k in unique.values():
        lines += c_struct(f"cj_{k.name}_record", k.name, k.equations, k.fields)
    lines.append("#endif")
    return "\n".join(lines) + "\n"


def c_struct(sname: str, label: str, comment: str, fields) -> list[str]:
    """Lines of one C11 struct `sname` laid out like the std430 record of `fields` (explicit
    padding members), with static asserts on its size and every offset, and a blank line."""
    fields = _fields(fields)
    offsets, stride = layout(fields)
    lines = [f"/* {label}: {comment} */", f"typedef struct {sname} {{"]
    end = 0
    for f, off in zip(fields, offsets, strict=True):
        if off > end:  # std430 alignment gap (vec2 on 8, vec3/vec4 on 16 bytes)
            lines.append(f"    uint8_t _pad_{f.name}[{off - end}];")
        lines.append(_c_field(f, off))
        end = off + f.size
    if stride > end:
        lines.append(f"    uint8_t _pad_end[{stride - end}];")
    lines.append(f"}} {sname};")
    lines.append(f"_Static_assert(sizeof({sname}) == {stride}, \"{label} stride\");")
    lines += [f"_Static_assert(offsetof({sname}, {f.name}) == {off}, \"{label}.{f.name}\");"
              for f, off in zip(fields, offsets, strict=True)]
    lines.append("")
    return lines
