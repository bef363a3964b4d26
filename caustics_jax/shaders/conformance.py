"""Conformance of the GLSL ports against the exported reference data, on a Vulkan device.

For each kernel: assemble `#version 450` + the record struct (generated from the export's
field list, the same one that lays out the `.bin` and the C header) + `common.glsl` +
`<kernel>.glsl` + a `main` that runs `cj_run` once per record; compile it to SPIR-V with
`glslangValidator`; run it with the small C host (`host.c`, built with `cc` against the
Vulkan loader) on the records with their outputs overwritten by NaN; read the records back
and compare the outputs with the reference (`export.compare`: max abs / rel / ULP error and
pass rate against the manifest tolerances).

    python -m caustics_jax.shaders.conformance DATA_DIR [--kernels ...] [--scenes ...] [--json out.json]

Scenes (start point, walk or one-step Newton, D, irradiance) are judged by `scene_conformance`.

Needs `glslangValidator` (Debian `glslang-tools`), a C compiler, the Vulkan headers and
loader (`libvulkan-dev`, `libvulkan1`) and a Vulkan driver (`mesa-vulkan-drivers` gives
lavapipe on the CPU). Where one is missing, `Unavailable` says which.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

from .. import export as ex
from .vulkan import LOCAL_SIZE, SHADER_DIR, Unavailable, build_host, compile_shader, glsl_struct, run_host


def shader_source(kernel_name: str, shader_dir: Path | None = None) -> str:
    """The complete compute shader of one kernel, ready for glslangValidator."""
    shader_dir = Path(shader_dir or SHADER_DIR)
    kernel = ex.KERNELS[kernel_name]
    return "\n".join([
        "#version 450",
        f"// caustics_jax conformance shader for '{kernel_name}' ({kernel.equations})",
        f"layout(local_size_x = {LOCAL_SIZE}) in;",
        glsl_struct(kernel),
        "layout(std430, binding = 0) readonly buffer RecordsIn { Record records_in[]; };",
        "layout(std430, binding = 1) writeonly buffer RecordsOut { Record records_out[]; };",
        "layout(push_constant) uniform Push { uint count; } push;",
        "#line 1 1",
        (shader_dir / "common.glsl").read_text(),
        "#line 1 2",
        (shader_dir / f"{kernel_name}.glsl").read_text(),
        "void main() {",
        "    uint i = gl_GlobalInvocationID.x;",
        "    if (i >= push.count) return;",
        "    Record r = records_in[i];",
        "    cj_run(r);",
        "    records_out[i] = r;",
        "}",
        "",
    ])


def _hide_outputs(manifest: dict, raw: bytes) -> bytes:
    """The records with every output field's bytes set to 0xFF (NaN / 0xFFFFFFFF): a shader
    that forgets to write an output cannot pass by echoing the reference."""
    buf = np.frombuffer(raw, np.uint8).copy().reshape(manifest["count"], manifest["stride"])
    for e in manifest["fields"]:
        if e["role"] == "output":
            size = 4 * int(np.prod(e["storage_shape"], dtype=np.int64))
            buf[:, e["offset"]: e["offset"] + size] = 0xFF
    return buf.tobytes()


def run_kernel(data_dir, kernel_name: str, work_dir, *, source: str | None = None, host: Path | None = None) -> dict:
    """Run one kernel's shader on the device against `data_dir/<kernel>.{json,bin}`.

    `source` replaces the assembled shader (to test a modified port). Returns
    `export.compare`'s report plus `device`. Raises Unavailable without a toolchain/device.
    """
    work = Path(work_dir)
    work.mkdir(parents=True, exist_ok=True)
    host = host or build_host(work)
    manifest, records = ex.load(data_dir, kernel_name)
    spv = compile_shader(source if source is not None else shader_source(kernel_name), work / f"{kernel_name}.spv")
    raw = (Path(data_dir) / f"{kernel_name}.bin").read_bytes()
    (work / f"{kernel_name}.in.bin").write_bytes(_hide_outputs(manifest, raw))
    out = work / f"{kernel_name}.out.bin"
    device, timing = run_host(host, spv, work / f"{kernel_name}.in.bin", out, manifest["count"], manifest["stride"])
    got = ex.read_records(manifest, out.read_bytes())
    report = ex.compare(manifest, records, got)
    report["device"], report["dispatch_seconds"] = device, timing["wall"]
    report["dispatch_cpu_seconds"] = timing["cpu"]
    return report


def run_conformance(data_dir, kernels=None, work_dir=None) -> list[dict]:
    """`run_kernel` for every kernel exported in `data_dir` (or `kernels`)."""
    names = kernels or [k for k in ex.KERNELS if (Path(data_dir) / f"{k}.json").exists()]
    if not names:
        raise ValueError(f"no exported kernels in {data_dir}")
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(work_dir or tmp)
        host = build_host(work)
        return [run_kernel(data_dir, k, work, host=host) for k in names]


def format_table(reports: list[dict]) -> str:
    """Markdown table: per kernel and output, max abs / rel / ULP error, tolerance and pass rate."""
    rows = ["| kernel | output | records | max abs | max rel | max ULP | tol abs | tol rel | max err/tol | pass rate |",
            "|---|---|---|---|---|---|---|---|---|---|"]
    for r in reports:
        for name, f in r["fields"].items():
            if "max_abs" in f:
                rows.append(f"| {r['kernel']} | {name} | {r['count']} | {f['max_abs']:.2e} | {f['max_rel']:.2e} | "
                            f"{f['max_ulp']} | {f['tol_abs']:.1e} | {f['tol_rel']:.1e} | {f['max_err_over_tol']:.2f} | "
                            f"{f['pass_rate']:.4f} |")
            else:
                rows.append(f"| {r['kernel']} | {name} (exact) | {r['count']} | - | - | - | 0 | 0 | - | "
                            f"{f['pass_rate']:.4f} |")
    rows += ["", "max ULP counts float32 steps between port and reference; near zero, where the steps are "
             "tiny, it is large even for errors far below the absolute tolerance, which is what judges there "
             "(a record passes when |port - ref| <= tol abs + tol rel * scale)."]
    return "\n".join(rows)


def main(argv=None, prog: str = "python -m caustics_jax.shaders.conformance") -> int:
    """The command line (`caustics-jax conformance` passes its own `prog`, which prefixes
    every message)."""
    from . import scene_conformance as sc

    p = argparse.ArgumentParser(prog=prog, description=__doc__.splitlines()[0])
    p.add_argument("data", help="directory written by `caustics-jax export`")
    p.add_argument("--kernels", nargs="+", default=None, choices=sorted(ex.KERNELS))
    p.add_argument("--scenes", nargs="+", default=None, metavar="SCENE",
                   help="scenes exported in DATA (built-in or your own mesh's; a name runs every solver's file "
                        "of that scene, a stem such as lagoon.newton one file; default: every one there)")
    p.add_argument("--json", default=None, help="write the reports as JSON here")
    args = p.parse_args(argv)
    data = Path(args.data)
    exported = sc.exported_scenes(data)  # by manifest: a mesh file's scene has the file's name
    chosen = {s: [e for e in exported if e == s or e.split(".")[0] == s] for s in args.scenes or []}
    missing = [s for s, stems in chosen.items() if not stems]
    if missing:
        print(f"{prog}: no exported scene {missing} in {data} (exported: {', '.join(exported) or 'none'})",
              file=sys.stderr)
        return 2
    kernels = args.kernels if args.kernels or args.scenes else [k for k in ex.KERNELS if (data / f"{k}.json").exists()]
    selected = list(dict.fromkeys(stem for stems in chosen.values() for stem in stems))
    scenes = selected if args.scenes else ([] if args.kernels else exported)
    if not kernels and not scenes:
        print(f"{prog}: no exported kernels or scenes in {data}", file=sys.stderr)
        return 2
    try:
        reports = run_conformance(data, kernels) if kernels else []
        scene_reports = sc.run_scenes(data, scenes) if scenes else []
    except Unavailable as exc:
        print(f"{prog}: skipped, {exc}", file=sys.stderr)
        return 3
    except ValueError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 2
    print(f"device: {(reports or scene_reports)[0]['device']}")
    if reports:
        print(format_table(reports))
    if scene_reports:
        print(sc.format_scene_table(scene_reports))
    if args.json:
        Path(args.json).write_text(json.dumps({"kernels": reports, "scenes": scene_reports}, indent=1) + "\n")
    failed = [r["kernel"] for r in reports if r["pass_rate"] < 1] + [f"{r['scene']} ({r['solver']})"
                                                                     for r in scene_reports if not r["passed"]]
    if failed:
        print(f"FAILED: {failed}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
