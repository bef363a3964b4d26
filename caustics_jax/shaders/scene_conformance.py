"""Conformance of the GLSL start point, walk or one-step Newton, D and irradiance against the
exported scene files (the walk's `<scene>` and the Newton's `<scene>.newton`).

The scene shader is `#version 450` + the seven structs of the scene file (generated from
`export.scene_records`, the layout that wrote the `.bin` and `caustics_scene.h`) + the
buffer bindings (0 lanes in, 1 lanes out, then `BINDINGS`: scene parameters, vertices,
faces, cell lines, cell faces, cell rows) + `SCENE_FILES`. One SPIR-V serves every scene
and both solvers (`cj_scene.solver`). The host (`host.c`) runs it once per
lane with every `output` and `reference` field of the lanes hidden (0xFF), and
`scene_report` judges the lanes it returns (docs/export.md "Scene conformance"):

- status agreement with the float32 solver of the testbed on at least
  `tolerance.status.agreement` (0.999) of the conditioned lanes (`conditioned = 1`: float32
  decides their status, `export.scene_writer`), disagreements tabulated by status pair,
  those of the other lanes separately;
- where both are FOUND, the port's point within the lane's `M_tol` of the testbed's;
- every FOUND point of the port checked in float64 (`testing.oracle.refraction_angle_error`
  at the port's face and barycentrics): silent wrong when the refraction-angle error exceeds
  `tol` plus 4x refract's float32 rounding bound there (`oracle.refraction_rounding_bound`);
  none allowed;
- `D` and `E` of every FOUND conditioned lane of the port against the float64 `D` and `E`
  at the port's own point, within the manifest's relative tolerance or `SAFETY` times the
  lane's own measured float32 error (`D_err`, `E_err`: near a caustic D cancels), whichever
  is larger; near TIR `D` tends to 0 and its relative error is unbounded.

Start points, crossings and iterations are compared and reported, not judged: a general
mesh's start point may pick another of the faces that meet at an edge.
"""

from __future__ import annotations

import tempfile
from collections import Counter
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from ..export import scene_records as sr
from ..export.tolerance import SAFETY
from ..runtime.precision import precision
from ..solvers import Status
from ..surface.mesh import SurfaceMesh
from ..testing.oracle import NumpyMesh, refraction_angle_error, refraction_rounding_bound
from ..transport.contribution import path_irradiance
from ..transport.differentials import ray_differential_D
from .vulkan import LOCAL_SIZE, SHADER_DIR, build_host, compile_shader, glsl_struct, run_host

#: GLSL files of the scene shader, in order, after the generated declarations.
SCENE_FILES = ("common.glsl", "scene_mesh.glsl", "start_point.glsl", "arcs.glsl", "walk.glsl", "newton.glsl",
               "scene_lane.glsl")
#: GLSL struct names of the scene buffers.
STRUCTS = {"scene": "SceneParams", "vertices": "Vertex", "faces": "Face", "lanes": "Lane", "cell_lines": "CellLine",
           "cell_faces": "CellFace", "cell_rows": "CellRow"}
#: The buffers after `lanes`, bound from 2 on in file order (`scene_records.BUFFERS`): the
#: GLSL variable of each is `cj_<buffer>` (one record for `scene`, an array for the others).
BINDINGS = tuple(name for name in sr.BUFFERS if name != "lanes")
#: Factor on refract's float32 rounding bound in the silent-wrong test.
ROUNDING_FACTOR = 4.0


def scene_shader_source(shader_dir: Path | None = None) -> str:
    """The complete compute shader of the scene lanes, ready for glslangValidator."""
    shader_dir = Path(shader_dir or SHADER_DIR)
    parts = ["#version 450",
             "// caustics_jax conformance shader for scene files (start point, walk or Newton, D, irradiance)",
             f"layout(local_size_x = {LOCAL_SIZE}) in;"]
    parts += [glsl_struct(fields, STRUCTS[name]) for name, fields in sr.BUFFERS.items()]
    parts += [
        "layout(std430, binding = 0) readonly buffer LanesIn { Lane lanes_in[]; };",
        "layout(std430, binding = 1) writeonly buffer LanesOut { Lane lanes_out[]; };",
    ]
    parts += [f"layout(std430, binding = {i + 2}) readonly buffer {STRUCTS[name]}Buffer {{ {STRUCTS[name]} "
              f"cj_{name}{'' if name == 'scene' else '[]'}; }};" for i, name in enumerate(BINDINGS)]
    parts += ["layout(push_constant) uniform Push { uint count; } push;"]
    for i, name in enumerate(SCENE_FILES):
        parts += [f"#line 1 {i + 1}", (shader_dir / name).read_text()]
    parts += ["void main() {", "    uint i = gl_GlobalInvocationID.x;", "    if (i >= push.count) return;",
              "    Lane r = lanes_in[i];", "    cj_run(r);", "    lanes_out[i] = r;", "}", ""]
    return "\n".join(parts)


def _hidden_lanes(entry: dict, raw: bytes) -> bytes:
    """The lane records with every output and reference field set to 0xFF (NaN, -1, 2^32 - 1):
    a port cannot pass by echoing the expected values."""
    buf = np.frombuffer(raw, np.uint8).copy().reshape(entry["count"], entry["stride"])
    for e in entry["fields"]:
        if e["role"] in ("output", "reference"):
            size = 4 * int(np.prod(e["storage_shape"], dtype=np.int64))
            buf[:, e["offset"]: e["offset"] + size] = 0xFF
    return buf.tobytes()


def run_scene(data_dir, scene: str, work_dir, *, source: str | None = None, host: Path | None = None,
              spv: Path | None = None, repeat: int = 1, keep_lanes: bool = False) -> dict:
    """Run the scene shader on `data_dir/<scene>.{json,bin}` and judge it (`scene_report`).

    `source` replaces the assembled shader (to test a modified port); `spv` reuses a compiled
    one. `repeat` dispatches run for the timing (`dispatch_seconds`: the fastest);
    `keep_lanes` adds the port's lane records (`port_lanes`, field arrays). Raises
    Unavailable without a toolchain or device.
    """
    work = Path(work_dir)
    work.mkdir(parents=True, exist_ok=True)
    host = host or build_host(work)
    manifest, buffers = sr.load_scene(data_dir, scene)
    raw = (Path(data_dir) / f"{scene}.bin").read_bytes()
    if spv is None:
        spv = compile_shader(source if source is not None else scene_shader_source(), work / "scene.spv")
    paths = {}
    for name, e in manifest["buffers"].items():
        chunk = raw[e["offset"]: e["offset"] + e["count"] * e["stride"]]
        paths[name] = work / f"{scene}.{name}.bin"
        paths[name].write_bytes(_hidden_lanes(e, chunk) if name == "lanes" else chunk)
    lanes = manifest["buffers"]["lanes"]
    out = work / f"{scene}.lanes.out.bin"
    device, timing = run_host(host, spv, paths["lanes"], out, lanes["count"], lanes["stride"],
                               [paths[name] for name in BINDINGS], repeat)
    got = sr.read_records(lanes, out.read_bytes())
    report = scene_report(manifest, buffers, got)
    report["device"], report["dispatch_seconds"] = device, timing["wall"]
    report["dispatch_cpu_seconds"] = timing["cpu"]
    report["device_type"], report["driver_version"] = timing["device_type"], timing["driver_version"]
    if keep_lanes:
        report["port_lanes"] = got
    return report


def _mesh64(buffers) -> SurfaceMesh:
    v, f = buffers["vertices"], buffers["faces"]
    with precision("float64"):
        return SurfaceMesh.from_arrays(v["position"].astype(np.float64), f["v"].astype(np.int64),
                                       v["normal"].astype(np.float64), dtype="float64")


def _transport64(mesh, lanes, face, ab):
    """float64 `D` and `E` at `(face, ab)` of each lane (the port's own points)."""
    with precision("float64"):
        V, N = mesh.triangle(jnp.asarray(np.maximum(face, 0)))
        f64 = {k: jnp.asarray(lanes[k], jnp.float64) for k in ("P", "L", "receiver_normal", "intensity", "sigma_t",
                                                               "eta")}
        ab = jnp.asarray(ab, jnp.float64)
        D, _ = ray_differential_D(V, N, f64["P"], f64["L"], ab, f64["eta"])
        E, _ = path_irradiance(V, N, f64["P"], f64["L"], ab, f64["eta"], f64["intensity"], f64["receiver_normal"],
                               f64["sigma_t"])
        return np.asarray(D), np.asarray(E)


def scene_report(manifest: dict, buffers: dict, got: dict) -> dict:
    """Judge a port's lanes `got` against the scene's expected lanes (module docstring)."""
    exp = buffers["lanes"]
    tol = manifest["options"]["tol"]
    eta = manifest["eta"]
    n = len(exp["status"])
    s_exp, s_got = exp["status"].astype(np.int64), got["status"].astype(np.int64)
    agree = s_exp == s_got
    conditioned = exp["conditioned"] == 1

    def pairs(mask):
        return Counter((Status(int(a)).name, Status(int(b)).name if int(b) in Status._value2member_map_
                        else str(int(b))) for a, b in zip(s_exp[mask], s_got[mask], strict=True))
    both = agree & (s_exp == Status.FOUND)
    dist = np.linalg.norm(got["M"].astype(np.float64) - exp["M"].astype(np.float64), axis=-1)
    far = both & ~(dist <= exp["M_tol"])
    found = s_got == Status.FOUND
    mesh = _mesh64(buffers)
    face = np.where(found, got["face"], 0).astype(np.int64)
    ok_face = found & (got["face"] >= 0) & (got["face"] < len(buffers["faces"]["v"]))
    angle = np.zeros(n)
    bound = np.zeros(n)
    P, L = exp["P"].astype(np.float64), exp["L"].astype(np.float64)
    if ok_face.any():
        ab = got["ab"][ok_face].astype(np.float64)
        angle[ok_face] = refraction_angle_error(mesh, face[ok_face], ab, P[ok_face], L[ok_face], eta)
        bound[ok_face] = refraction_rounding_bound(NumpyMesh.from_mesh(mesh), face[ok_face], ab, P[ok_face], eta,
                                                   np.float32)
    silent = found & ~(ok_face & (angle <= tol + ROUNDING_FACTOR * bound))
    D64, E64 = _transport64(mesh, exp, face, got["ab"])
    checks = {}
    for name, ref in (("D", D64), ("E", E64)):
        rel = np.maximum(manifest["tolerance"][name]["rel"], SAFETY * exp[f"{name}_err"].astype(np.float64))
        err = np.abs(got[name].astype(np.float64) - ref)
        bad = found & conditioned & ~(err <= rel * np.abs(ref) + 1e-30)
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.where(found & conditioned & (np.abs(ref) > 0), err / np.abs(ref), 0.0)
        checks[name] = {"violations": int(bad.sum()), "max_rel": float(r.max(initial=0.0)),
                        "tol_rel": manifest["tolerance"][name]["rel"],
                        "max_over_lane_tol": float(np.max(np.where(found & conditioned, r / rel, 0.0), initial=0.0)),
                        "lanes": np.nonzero(bad)[0].tolist()[:20]}
    start_same = (exp["start_found"] == got["start_found"])
    start_face_same = start_same & ((exp["start_face"] == got["start_face"]) | (exp["start_found"] == 0))
    agreement = float(np.mean(agree[conditioned])) if conditioned.any() else 1.0
    crit = manifest["tolerance"]["status"]["agreement"]
    passed = (agreement >= crit and not far.any() and not silent.any()
              and all(c["violations"] == 0 for c in checks.values()))
    return {
        "scene": manifest["scene"], "solver": manifest.get("solver", "walk"), "lanes": n, "passed": bool(passed),
        "conditioned_lanes": int(conditioned.sum()), "status_agreement": agreement, "status_agreement_required": crit,
        "status_agreement_all_lanes": float(np.mean(agree)),
        "disagreements": {f"{a} -> {b}": c for (a, b), c in sorted(pairs(~agree & conditioned).items())},
        "disagreements_unconditioned": {f"{a} -> {b}": c for (a, b), c in sorted(pairs(~agree & ~conditioned).items())},
        "disagreeing_lanes": np.nonzero(~agree & conditioned)[0].tolist()[:50],
        "found_testbed": int(np.sum(s_exp == Status.FOUND)), "found_port": int(found.sum()),
        "both_found": int(both.sum()), "M_outside_tol": int(far.sum()),
        "M_outside_lanes": np.nonzero(far)[0].tolist()[:20],
        "M_distance_max_m": float(dist[both].max(initial=0.0)),
        "M_distance_over_tol_max": float((dist[both] / exp["M_tol"][both]).max(initial=0.0)),
        "silent_wrong": int(silent.sum()), "silent_lanes": np.nonzero(silent)[0].tolist()[:20],
        "angle_error_max_rad": float(angle[found].max(initial=0.0)),
        # FOUND in float32 where float64 reflects totally: within refract's rounding of k = 0
        "found_but_tir_in_float64": int(np.sum(found & ok_face & (angle == np.pi))),
        "D": checks["D"], "E": checks["E"],
        "start_found_agreement": float(np.mean(start_same)),
        "start_face_agreement": float(np.mean(start_face_same)),
        "crossed_agreement": float(np.mean(got["crossed"] == exp["crossed"])),
        "iterations_agreement": float(np.mean(got["iterations"] == exp["iterations"])),
        "iterations_testbed": int(exp["iterations"].sum()), "iterations_port": int(got["iterations"].sum()),
    }


def run_scenes(data_dir, scenes=None, work_dir=None, repeat: int = 1) -> list[dict]:
    """`run_scene` for every scene exported in `data_dir` (or `scenes`), one compiled shader."""
    data = Path(data_dir)
    names = scenes or exported_scenes(data)
    if not names:
        raise ValueError(f"no exported scenes in {data_dir}")
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(work_dir or tmp)
        host = build_host(work)
        spv = compile_shader(scene_shader_source(), work / "scene.spv")
        return [run_scene(data, s, work, host=host, spv=spv, repeat=repeat) for s in names]


def exported_scenes(data_dir) -> list[str]:
    """File stems of the scene files exported in `data_dir` (their manifests), sorted: the
    built-in scenes and a mesh file's (`caustics-jax export --scene PATH`) alike, the walk's
    `<scene>` and the Newton's `<scene>.newton` (`scene_writer.scene_stem`)."""
    return sorted(p.stem for p in Path(data_dir).glob("*.json") if _is_scene(p))


def _is_scene(path: Path) -> bool:
    import json

    try:
        return "buffers" in json.loads(path.read_text())
    except (OSError, ValueError):
        return False


def format_scene_table(reports: list[dict]) -> str:
    """Markdown table: per scene, status agreement, disagreements by pair, point, silent, D, E."""
    rows = ["| scene | solver | lanes (conditioned) | FOUND testbed / port | status agreement, conditioned (all) | "
            "disagreements, conditioned lanes (testbed -> port) | disagreements, other lanes | "
            "both FOUND, M within M_tol | max dist / M_tol | silent wrong | D max rel (max / lane tol) | "
            "E max rel (max / lane tol) | "
            "start face agreement | crossings / iterations agreement |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in reports:
        dis = ", ".join(f"{k}: {v}" for k, v in r["disagreements"].items()) or "-"
        unst = ", ".join(f"{k}: {v}" for k, v in r["disagreements_unconditioned"].items()) or "-"
        rows.append(f"| {r['scene']} | {r['solver']} | {r['lanes']} ({r['conditioned_lanes']}) | "
                    f"{r['found_testbed']} / {r['found_port']} | "
                    f"{r['status_agreement']:.4f} ({r['status_agreement_all_lanes']:.4f}) | {dis} | {unst} | "
                    f"{r['both_found'] - r['M_outside_tol']}/{r['both_found']} | "
                    f"{r['M_distance_over_tol_max']:.3f} | {r['silent_wrong']} | "
                    f"{r['D']['max_rel']:.1e} ({r['D']['max_over_lane_tol']:.2f}) | {r['E']['max_rel']:.1e} "
                    f"({r['E']['max_over_lane_tol']:.2f}) | {r['start_face_agreement']:.4f} | "
                    f"{r['crossed_agreement']:.4f} / {r['iterations_agreement']:.4f} |")
    return "\n".join(rows)
