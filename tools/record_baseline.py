"""Record the baseline lanes: what `caustics_jax.solve` returns on fixed inputs, lane by lane.

Three scenes (the wavy pool with its default waves, a jittered heightfield, the lagoon) in
float32 and float64, each solved by the walk (alone, and with its default Newton fallback) and by one-step Newton
(`newton-hv-step` of the compare configurations). Per case it saves status, triangle,
iterations, found, point and barycentric, with the inputs (P, L) and a digest of the mesh,
to a compressed `.npz`. `tests/test_baseline.py` loads this file, builds the same cases
with `scene_lanes()` and `solve_case()` and checks that the installed package reproduces
them exactly.

It uses only public names (`caustics_jax`, `caustics_jax.testing`), so the same script runs
on the package before and after its modules move. Record from a checkout of the commit:

    PYTHONPATH=/path/to/checkout python tools/record_baseline.py tests/data/baseline_<commit>.npz
"""

from __future__ import annotations

import argparse
import hashlib
import json
import pathlib
import subprocess

import jax
import numpy as np

import caustics_jax as cj
from caustics_jax.testing import jittered_heightfield, planted_mesh_paths

DTYPES = ("float32", "float64")
#: (method, options) of each solver configuration; "newton-hv-step" as in the compare tool;
#: "walk" is the walk alone (seed 001's method, what the GLSL walk runs), "walk-fallback"
#: the default `Walk()` (the one-step Newton on the lanes the walk ends without a path).
METHODS = {
    "walk": ("walk", {"fallback": "none"}),
    "walk-fallback": ("walk", {}),
    "newton-hv-step": ("newton", {"stepping": "one_step", "constraint": "half_vector"}),
}
FIELDS = ("status", "triangle", "iterations", "found", "point", "barycentric")
#: The generation parameters, saved with the data. Mesh sizes are those of tests/test_walk.py
#: (2048 triangles), so the solver programs compiled for them are shared. Planted paths on
#: every face (margin 0) and up to 45 degrees off the normal: some lanes miss the surface,
#: leave the mesh or end in total internal reflection, not only FOUND.
PLANTED = {"seed": 7, "margin": 0.0, "max_angle_deg": 45.0, "height": (2.0, 4.0)}
PARAMS = {
    "wavy_pool": {"n_triangles": 2048, "n_receivers": 16, "planted": 256},
    "jittered_heightfield": {"n": 32, "seed": 1, "planted": 512},
    "lagoon": {"n_triangles": 2048, "n_receivers": 16, "planted": 256},
}
SCENES = tuple(PARAMS)


def scene_lanes(scene: str, dtype: str):
    """`(mesh, P, L)` of `scene` in `dtype`. The pool and the lagoon: the scene's receivers
    under its point light, then paths planted on its float64 surface; the jittered
    heightfield: planted paths only. float64 must be on (`cj.enable_x64()`)."""
    p = PARAMS[scene]
    if scene == "jittered_heightfield":
        mesh = jittered_heightfield(p["n"], seed=p["seed"], dtype=dtype)
        planted = planted_mesh_paths(jittered_heightfield(p["n"], seed=p["seed"]), p["planted"], **PLANTED)
        return mesh, planted.P.astype(dtype), planted.L.astype(dtype)
    make = {"wavy_pool": cj.scenes.wavy_pool, "lagoon": cj.scenes.lagoon}[scene]
    sc = make(p["n_triangles"], n_receivers=p["n_receivers"], dtype=dtype)
    planted = planted_mesh_paths(make(p["n_triangles"], dtype="float64").surface, p["planted"], **PLANTED)
    P = np.concatenate([np.asarray(sc.receivers), planted.P.astype(dtype)])
    L = np.concatenate([np.asarray(sc.lights.endpoint(sc.receivers)), planted.L.astype(dtype)])
    return sc.surface, P, L


def mesh_digest(mesh) -> str:
    """sha256 of the mesh's vertices, faces and normals (their bytes and dtypes)."""
    h = hashlib.sha256()
    for x in (mesh.vertices, mesh.faces, mesh.normals):
        x = np.ascontiguousarray(np.asarray(x))
        h.update(str(x.dtype).encode())
        h.update(x.tobytes())
    return h.hexdigest()


def baseline_cases():
    """`(scene, dtype, mesh, P, L)` for every scene and dtype, in a fixed order."""
    for scene in SCENES:
        for dtype in DTYPES:
            yield (scene, dtype, *scene_lanes(scene, dtype))


def solve_case(mesh, P, L, config: str) -> dict:
    """The recorded fields of `cj.solve(mesh, P, L)` with solver configuration `config`."""
    method, options = METHODS[config]
    sol = cj.solve(mesh, P, L, method=method, **options)
    return {field: np.asarray(getattr(sol, field)) for field in FIELDS}


def record() -> dict:
    """Every case's inputs and results as `.npz` entries `scene/dtype/...`."""
    out = {}
    for scene, dtype, mesh, P, L in baseline_cases():
        key = f"{scene}/{dtype}"
        out[f"{key}/P"], out[f"{key}/L"] = P, L
        out[f"{key}/mesh_sha256"] = np.array(mesh_digest(mesh))
        for config in METHODS:
            for field, value in solve_case(mesh, P, L, config).items():
                out[f"{key}/{config}/{field}"] = value
            status = out[f"{key}/{config}/status"]
            counts = {cj.Status(s).name: int(c) for s, c in zip(*np.unique(status, return_counts=True), strict=True)}
            print(f"{key}/{config}: {len(status)} lanes, {counts}")
    return out


def _commit(path: pathlib.Path) -> str:
    try:
        return subprocess.run(["git", "-C", str(path), "rev-parse", "HEAD"], capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=pathlib.Path, help="the .npz file to write")
    args = parser.parse_args(argv)
    cj.enable_x64()  # as tests/conftest.py does: float32 cases run with x64 on too
    package = pathlib.Path(cj.__file__).resolve().parent
    print(f"caustics_jax {cj.__version__} from {cj.__file__}")
    data = record()
    meta = {"commit": _commit(package), "caustics_jax": cj.__version__, "jax": jax.__version__,
            "backend": jax.default_backend(), "scenes": PARAMS, "planted": PLANTED, "dtypes": DTYPES,
            "methods": METHODS, "fields": FIELDS}
    data["params"] = np.array(json.dumps(meta, sort_keys=True))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(args.out, **data)
    print(f"wrote {args.out} ({args.out.stat().st_size} bytes), commit {meta['commit']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
