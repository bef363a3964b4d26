"""The solver comparison job behind `caustics-jax compare` and `make demo`.

One run measures, per solver configuration and dtype, on the same scene and receivers:

- success rate against the exhaustive float64 reference (`method="exhaustive"`) on a
  subset of the receivers (`ref_n` lanes; the culled reference costs a fraction of a
  millisecond per lane on meshes of 100k triangles, docs/solvers.md, so any mesh gets one):
  the fraction of lanes with at least one solution where the solver returned one, and
  the fraction where it returned the one nearest the start point `M0`;
- position error (m) of each returned point against the nearest reference solution (on
  the reference subset) and refraction-angle error (rad) of every found lane, evaluated
  in float64 on the float64 mesh (`testing.oracle.refraction_angle_error`), so float32 lanes
  are charged for their rounding too;
- iterations (walk: triangle crossings plus refinement steps; Newton: optimistix steps
  over all patches and starts), compile time (first call minus a steady call) and
  throughput (lanes / median wall time of `repeats` steady calls, start points
  included);
- a Pareto sweep: the same measurements on a smaller lane subset over several
  acceptance tolerances; tolerances and iteration caps are traced arguments of the
  solvers, so a sweep compiles once per configuration.

Timings are only comparable within one run (same machine, same load): report ratios.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from pathlib import Path

import jax
import numpy as np

from ..accel.start_points import start_points
from ..runtime.arguments import (
    check_bool,
    check_eta,
    check_fits,
    check_int,
    check_real,
    check_scene_scale,
    is_real_scalar,
)
from ..runtime.precision import precision
from ..runtime.progress import progress
from ..solvers import solve
from ..solvers.options import default_tol
from ..surface import scenes
from ..surface.lights import Directional, light_points, scene_size
from ..surface.scenes import MAX_TRIANGLES
from ..testing.oracle import NumpyMesh, barycentric_point, refraction_angle_error
from .reporting import log, stats

# name -> (method, options). "best optimistix Newton" is chosen among the newton-* rows.
CONFIGS: dict[str, tuple[str, dict]] = {
    "walk": ("walk", {}),
    "walk-bisection": ("walk", {"bracket": "bisection"}),
    # The walk without its Newton fallback: seed 001's method alone, what the GLSL walk runs.
    "walk-alone": ("walk", {"fallback": "none"}),
    "newton-hv": ("newton", {"solver": "newton", "constraint": "half_vector"}),
    "newton-ad": ("newton", {"solver": "newton", "constraint": "angle_difference"}),
    "chord-hv": ("newton", {"solver": "chord", "constraint": "half_vector"}),
    "lm-hv": ("newton", {"solver": "levenberg_marquardt", "constraint": "half_vector"}),
    "dogleg-hv": ("newton", {"solver": "dogleg", "constraint": "half_vector"}),
    "newton-hv-sms4": ("newton", {"solver": "newton", "constraint": "half_vector", "n_starts": 4}),
    # One Newton step, then project back onto the surface, as Cycles' MNEE and Mitsuba's SMS
    # step (`Newton(stepping="one_step")`): the strongest Newton baseline on the default pool
    # (docs/solvers.md "Throughput and the machine's limit").
    "newton-hv-step": ("newton", {"stepping": "one_step", "constraint": "half_vector"}),
    "newton-ad-step": ("newton", {"stepping": "one_step", "constraint": "angle_difference"}),
    "newton-hv-step-gentle": ("newton", {"stepping": "one_step", "constraint": "half_vector", "initial_step": 0.1}),
    # The chunked lane scheduler (fixed chunks of 256 lanes, each until its slowest lane), the
    # baseline the slot pool is compared with.
    "walk-chunked": ("walk", {"scheduler": "chunked"}),
    "newton-hv-chunked": ("newton", {"solver": "newton", "constraint": "half_vector", "scheduler": "chunked"}),
}
DEFAULT_CONFIGS = ("walk", "newton-hv-step", "newton-hv", "newton-ad", "lm-hv")
SCENES: dict[str, Callable] = {
    "wavy": lambda n, dt, **kw: scenes.wavy_pool(n, dtype=dt, **kw),
    "wavy_steep": lambda n, dt, **kw: scenes.wavy_pool(n, amplitude=0.08, dtype=dt, **kw),
    "wavy_jittered": lambda n, dt, **kw: scenes.wavy_pool(n, choppiness=0.5, dtype=dt, **kw),
    # Past the focal distance: steep waves over a floor 3 m down, where several paths reach
    # one receiver (the post-focal transect of experiments/irradiance_agreement.py).
    "postfocal": lambda n, dt, **kw: scenes.wavy_pool(n, dtype=dt, **{"amplitude": 0.3, "depth": 3.0, **kw}),
    "flat": lambda n, dt, **kw: scenes.flat_pool(n, dtype=dt, **kw),
    "lagoon": lambda n, dt, **kw: scenes.lagoon(n, dtype=dt, **kw),
}
# `--scene PATH`: a mesh file trimesh reads (`surface.scenes.load_mesh`).
MESH_SUFFIXES = scenes.MESH_SUFFIXES


def is_scene_path(scene: str) -> bool:
    """True when `scene` names a mesh file (by its suffix, `MESH_SUFFIXES`) rather than a named scene."""
    return str(scene).lower().endswith(MESH_SUFFIXES)


def load_scene(scene: str, n_triangles: int = 8192, dtype="float64", *, light=None,
               floor_depth: float | None = None) -> scenes.Scene:
    """A named scene of `SCENES` at `n_triangles`, or a mesh file (OBJ, PLY, GLB, ...) read by
    trimesh with the floor and light of `surface.scenes.scene_around` (`n_triangles` unused
    then). `light` (a point, or a `Directional`: the sun) and `floor_depth` (m below the
    surface; the named pools' `depth`) replace the scene's own."""
    if not is_scene_path(scene):
        if scene not in SCENES:
            raise ValueError(f"scene must be one of {sorted(SCENES)} or a mesh file "
                             f"({', '.join(MESH_SUFFIXES)}), got {scene!r}")
        if isinstance(light, Directional):  # the generators' directional light: toward it
            kw = {"light": "directional", "light_position": tuple(float(x) for x in light.toward)}
        else:
            kw = {} if light is None else {"light_position": tuple(float(x) for x in light)}
        return SCENES[scene](n_triangles, dtype, **kw, **({} if floor_depth is None else {"depth": floor_depth}))
    surface = scenes.load_mesh(scene, dtype)
    name = f"{Path(scene).name} ({surface.faces.shape[0]} triangles)"
    return scenes.scene_around(surface, light=light, floor_depth=floor_depth, name=name)


# Acceptance tolerances of the Pareto sweep (|f| = sine of the angle error), per dtype;
# float32 stops at 1e-6, the noise floor of f in float32 (docs/kernels.md, float32 audit).
SWEEP_TOLS = {"float32": (1e-2, 1e-3, 1e-4, 1e-5, 1e-6),
              "float64": (1e-2, 1e-4, 1e-6, 1e-8, 1e-10, 1e-12)}


#: Largest `n` (and `ref_n`, `sweep_n`): 2^26 lanes hold 3 GiB of float64 receivers and
#: lights before any solver state; above it a run is a typo, refused before any work.
MAX_LANES = 2**26


@dataclasses.dataclass
class CompareConfig:
    """What to compare. `n` receivers on a regular floor grid of the scene, lights as the scene."""

    scene: str = "wavy"
    n_triangles: int = 8192
    n: int = 100_000
    dtypes: tuple[str, ...] = ("float32", "float64")
    configs: tuple[str, ...] = DEFAULT_CONFIGS
    ref_n: int = 1024
    sweep_n: int = 8192
    sweep: bool = True
    repeats: int = 2
    eta: float = 1.333
    seed: int = 0
    keep_lanes: bool = False  # per-lane statuses and receivers in the report (floor maps of failures)
    light: tuple[float, float, float] | Directional | None = None  # a point light or the sun replacing the scene's
    frame: tuple[int, int] | None = None  # (width, height): also time one frame of receivers (seed 001's unit)
    floor_depth: float | None = None  # the receivers' floor, m below the surface (the pools' depth)

    def validate(self) -> None:
        """Raise `ValueError` naming the first bad field and its valid range (before any work)."""
        if not isinstance(self.scene, str):
            raise ValueError(f"scene must be a scene name or a mesh file path (str), got {self.scene!r}")
        for name in ("dtypes", "configs"):
            value = getattr(self, name)
            if not isinstance(value, tuple | list) or not value or not all(isinstance(v, str) for v in value):
                raise ValueError(f"{name} must be a non-empty tuple of names, got {value!r}")
        check_int("n", self.n, 1, MAX_LANES)
        check_int("n_triangles", self.n_triangles, 8, MAX_TRIANGLES)
        check_int("ref_n", self.ref_n, 0, MAX_LANES)
        check_int("sweep_n", self.sweep_n, 1, MAX_LANES)
        check_int("repeats", self.repeats, 1, 1000)
        check_int("seed", self.seed, 0, 2**32 - 2)  # the reference subset draws with seed + 1
        check_eta(self.eta)
        check_bool("sweep", self.sweep)
        check_bool("keep_lanes", self.keep_lanes)
        if self.light is not None and not isinstance(self.light, Directional):
            light = np.asarray(self.light, float) if all(is_real_scalar(x) for x in self.light) else None
            if light is None or light.shape != (3,) or not np.all(np.isfinite(light)):
                raise ValueError(f"light must be one finite point (x, y, z), got {self.light!r}")
        if self.floor_depth is not None:
            check_real("floor_depth", self.floor_depth, 0, lo_open=True)
        if self.frame is not None:
            if not isinstance(self.frame, tuple | list) or len(self.frame) != 2:
                raise ValueError(f"frame must be (width, height) in receivers, got {self.frame!r}")
            check_int("frame width", self.frame[0], 1, 8192)
            check_int("frame height", self.frame[1], 1, 8192)
        if not is_scene_path(self.scene) and self.scene not in SCENES:
            raise ValueError(f"scene must be one of {sorted(SCENES)} or a mesh file "
                             f"({', '.join(MESH_SUFFIXES)}), got {self.scene!r}")
        if is_scene_path(self.scene) and not Path(self.scene).expanduser().is_file():
            raise ValueError(f"scene file {self.scene!r} does not exist")
        unknown = [c for c in self.configs if c not in CONFIGS]
        if unknown:
            raise ValueError(f"unknown solver configs {unknown}; known: {sorted(CONFIGS)}")
        bad = [d for d in self.dtypes if d not in ("float32", "float64")]
        if bad:
            raise ValueError(f"dtypes must be float32 and/or float64, got {bad}")
        for dtype in self.dtypes:  # as solve refuses it, before the run
            check_fits("eta", self.eta, np.dtype(dtype), positive=True)

    def expected_solves(self) -> int:
        """Solver lanes the run will compute: `n` per configuration and dtype, timed
        `repeats + 1` times, plus the sweep (the figure's points)."""
        total = 0
        for dtype in self.dtypes:
            total += self.n * (self.repeats + 1)
            if self.sweep:
                total += min(self.sweep_n, self.n) * (1 + max(1, self.repeats - 1)) * len(SWEEP_TOLS.get(dtype, ()))
        return len(self.configs) * total


def scene_arrays(cfg: CompareConfig):
    """The float64 scene, `n` receivers (floor grid) and their light endpoints, as numpy."""
    side = int(np.ceil(np.sqrt(cfg.n)))
    sc = load_scene(cfg.scene, cfg.n_triangles, "float64", light=cfg.light, floor_depth=cfg.floor_depth)
    lo = np.asarray(sc.surface.vertices)[:, :2].min(0)
    hi = np.asarray(sc.surface.vertices)[:, :2].max(0)
    depth = float(np.asarray(sc.receivers)[0, 2])
    u = (np.arange(side) + 0.5) / side
    X, Y = np.meshgrid(lo[0] + u * (hi[0] - lo[0]), lo[1] + u * (hi[1] - lo[1]), indexing="xy")
    P = np.stack([X.ravel(), Y.ravel(), np.full(side * side, depth)], -1)
    P = P[np.linspace(0, len(P) - 1, cfg.n).astype(int)]  # n lanes spread over the grid
    # A directional light as its points on the receivers' rays at float32's limit distance
    # (surface/lights.py): one set of lanes for both dtypes and the float64 reference.
    V = np.asarray(sc.surface.vertices)
    L = light_points(sc.lights.source(0), P, scene_size(V, P), np.float32).points
    return sc, NumpyMesh.from_mesh(sc.surface), P, L


def _timed(fn, repeats: int):
    """`(out, compile_s, steady_s, cached)`: compile time = first call minus the median
    steady call; `cached` says the first call loaded its programs from JAX's persistent
    compilation cache (`caustics_jax.runtime.compilation`) and compiled none that JAX would cache
    (one taking over `jax_persistent_cache_min_compile_time_secs`, 1 s), so `compile_s` is
    a load time then. A first call that loaded some programs and compiled a solver's
    (after a code change) is not `cached`: its compile time is real."""
    hits, misses = [], []

    def on_event(event, **_):
        if event == "/jax/compilation_cache/cache_hits":
            hits.append(event)
        elif event == "/jax/compilation_cache/cache_misses":  # JAX writes a compiled program
            misses.append(event)

    jax.monitoring.register_event_listener(on_event)
    try:
        t = time.perf_counter()
        out = jax.block_until_ready(fn())
        first = time.perf_counter() - t
    finally:
        jax.monitoring.unregister_event_listener(on_event)
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - t)
    steady = float(np.median(times))
    return out, max(first - steady, 0.0), steady, bool(hits) and not misses


def _errors(sol, ref_mesh, P, L, eta, ref):
    """Angle errors of found lanes; position errors and success on the reference subset."""
    found = np.asarray(sol.found)
    tri = np.asarray(sol.triangle)
    ab = np.asarray(sol.barycentric, np.float64)
    angle = refraction_angle_error(ref_mesh, tri[found], ab[found], P[found], L[found], eta)
    out = {"found": float(found.mean()), "angle": angle}
    if ref is not None:
        idx, pts, count = ref["idx"], ref["all_points"], ref["count"]
        has = count > 0
        f_ref = found[idx]
        M = barycentric_point(ref_mesh.triangles(np.maximum(tri[idx], 0))[0], ab[idx])
        d = np.linalg.norm(pts - M[:, None], axis=-1)
        d = np.where(np.arange(pts.shape[1])[None] < count[:, None], d, np.inf)
        nearest = d.min(1)
        out["position"] = nearest[f_ref & has]
        out["success"] = float((f_ref & has).sum() / max(has.sum(), 1))
        # returned the reference solution nearest M0 (within 1e-4 m, float32 rounding included)
        same = np.argmin(d, 1) == ref["nearest_M0"]
        out["nearest_M0"] = float((f_ref & has & same & (nearest < 1e-4)).sum() / max(has.sum(), 1))
        out["spurious"] = int((f_ref & ~has).sum())
    return out


def solution_counts(lanes_with) -> str:
    """`lanes with 0 / 1 / 2 solutions: 3 / 500 / 9` from `lanes_with[k]`, the lanes with `k`
    solutions (`np.bincount` of the per-lane counts)."""
    k = [int(x) for x in lanes_with]
    shown = [i for i in range(len(k)) if k[i]]
    return (f"lanes with {' / '.join(map(str, shown))} solutions: "
            f"{' / '.join(str(int(k[i])) for i in shown)}") if shown else "no lanes"


def reference(cfg: CompareConfig, sc, P, L):
    """Exhaustive float64 solutions on `ref_n` lanes (None when `ref_n` is 0)."""
    if cfg.ref_n == 0:
        log("no exhaustive reference (ref_n = 0)")
        return None
    rng = np.random.default_rng(cfg.seed + 1)
    idx = np.sort(rng.choice(len(P), min(cfg.ref_n, len(P)), replace=False))
    t = time.perf_counter()
    ex = solve(sc.surface, P[idx], L[idx], eta=cfg.eta, method="exhaustive", return_all=True)
    M0 = np.asarray(ex.solution.start_point)
    d = np.linalg.norm(ex.all_points - M0[:, None], axis=-1)
    d = np.where(np.arange(ex.all_points.shape[1])[None] < ex.count[:, None], d, np.inf)
    seconds = time.perf_counter() - t
    log(f"exhaustive reference: {len(idx)} lanes on {sc.surface.faces.shape[0]} faces in {seconds:.1f} s "
        f"(its compilation included); {solution_counts(np.bincount(ex.count))}")
    return {"idx": idx, "all_points": ex.all_points, "count": ex.count,
            "nearest_M0": np.argmin(d, 1), "seconds": time.perf_counter() - t}


def _run_dtype(cfg, dtype, sc64, ref_mesh, P, L, ref, results, sweeps, bar):
    with precision(dtype):
        mesh = sc64.surface.astype(dtype)
        Pd, Ld = np.asarray(P, dtype), np.asarray(L, dtype)
        for name in cfg.configs:
            method, opts = CONFIGS[name]
            log(f"[{dtype}] {name}: {cfg.n} lanes ...")
            t0 = time.perf_counter()
            try:
                sol, compile_s, steady, cached = _timed(
                    lambda m=method, o=opts: solve(mesh, Pd, Ld, eta=cfg.eta, method=m, **o),
                    cfg.repeats)
            except ValueError as exc:  # e.g. a solver unavailable in this dtype
                log(f"  skipped: {exc}")
                bar.update(1)
                continue
            err = _errors(sol, ref_mesh, P, L, cfg.eta, ref)
            it = np.asarray(sol.iterations)[np.asarray(sol.found)]
            row = {
                "config": name, "method": method, "options": opts, "dtype": dtype,
                "n": cfg.n, "found": err["found"],
                "success": err.get("success"), "nearest_M0": err.get("nearest_M0"),
                "spurious": err.get("spurious"),
                "angle_error_rad": stats(err["angle"]),
                "position_error_m": stats(err["position"]) if "position" in err else None,
                "iterations": {"median": float(np.median(it)) if it.size else float("nan"),
                               "p99": float(np.quantile(it, 0.99)) if it.size else float("nan")},
                "compile_s": compile_s, "compile_cached": cached, "seconds": steady, "solves_per_s": cfg.n / steady,
                "status": sol.summary(), "tol": opts.get("tol", default_tol(dtype)),
            }
            if cfg.keep_lanes:
                row["lane_status"] = np.asarray(sol.status).astype(int).tolist()
            results.append(row)
            log(f"  {row['solves_per_s']:.0f} solves/s, found {row['found']:.4f}, "
                f"compile {compile_s:.1f} s ({time.perf_counter() - t0:.0f} s)")
            if cfg.sweep:
                sweeps.extend(_sweep(cfg, name, method, opts, dtype, mesh, Pd, Ld, ref_mesh,
                                     P, L))
            bar.update(1)


def _sweep(cfg, name, method, opts, dtype, mesh, Pd, Ld, ref_mesh, P, L):
    n = min(cfg.sweep_n, len(P))
    idx = np.linspace(0, len(P) - 1, n).astype(int)
    out = []
    for tol in SWEEP_TOLS[dtype]:
        sol, _, steady, _ = _timed(
            lambda t=tol: solve(mesh, Pd[idx], Ld[idx], eta=cfg.eta, method=method,
                                **{**opts, "tol": t}), max(1, cfg.repeats - 1))
        err = _errors(sol, ref_mesh, P[idx], L[idx], cfg.eta, None)
        out.append({"config": name, "dtype": dtype, "tol": tol, "n": n,
                    "us_per_solve": 1e6 * steady / n, "found": err["found"],
                    "angle_error_rad": stats(err["angle"])})
    log(f"  sweep over {len(SWEEP_TOLS[dtype])} tolerances on {n} lanes done")
    return out


def run(cfg: CompareConfig) -> dict:
    """Run the comparison; returns a JSON-serialisable dict (rows, sweep, reference)."""
    cfg.validate()
    with precision("float64"):
        sc64, ref_mesh, P, L = scene_arrays(cfg)
        for dtype in cfg.dtypes:  # every dtype's scale band, before anything runs (a mesh file)
            check_scene_scale(np.asarray(sc64.surface.vertices), (P, L), np.dtype(dtype))
        n_cross = int(np.asarray(start_points(sc64.surface, P, L)[2]).sum())
        ref = reference(cfg, sc64, P, L)
    results, sweeps = [], []
    with progress(total=len(cfg.dtypes) * len(cfg.configs), desc="compare", unit="config") as bar:
        for dtype in cfg.dtypes:
            _run_dtype(cfg, dtype, sc64, ref_mesh, P, L, ref, results, sweeps, bar)
    frames = frame_times(cfg, sc64, results)
    report = {
        "scene": sc64.name, "n": cfg.n, "lanes_crossing_surface": n_cross, "frames": frames,
        "config": {k: v for k, v in dataclasses.asdict(cfg).items()},
        "reference": None if ref is None else {
            "lanes": len(ref["idx"]), "seconds": ref["seconds"],
            "solutions_per_lane": np.bincount(ref["count"]).tolist()},
        "rows": results, "sweep": sweeps,
        "platform": jax.default_backend(), "devices": [str(d) for d in jax.devices()],
    }
    if cfg.keep_lanes:
        report["receivers"] = P.tolist()
    return report


#: The configurations `frame_times` times: the walk against the strongest baseline.
FRAME_CONFIGS = ("walk", "newton-hv-step")


def frame_times(cfg: CompareConfig, sc64, rows: list[dict]) -> list[dict]:
    """Seconds to solve one frame of `cfg.frame = (width, height)` receivers (seed 001 §5
    reports its timings per 960x720 frame): a regular grid on the floor under the
    surface's xy extent, the scene's light. Only the race a port decides (`FRAME_CONFIGS`,
    the walk and the strongest Newton) and only in float32, what shaders run (else the
    table's first dtype): the optimistix Newtons take 10-30 s per frame, which had made
    `make demo` take 11 min instead of about 3. One untimed call first (the table's runs
    compiled the programs: blocks of one size), then one timed; the first call's compile
    time is the table's `compile`."""
    if cfg.frame is None:
        return []
    width, height = cfg.frame
    V = np.asarray(sc64.surface.vertices)
    lo, hi = V[:, :2].min(0), V[:, :2].max(0)
    depth = float(np.asarray(sc64.receivers)[0, 2])
    X, Y = np.meshgrid(lo[0] + (np.arange(width) + 0.5) / width * (hi[0] - lo[0]),
                       lo[1] + (np.arange(height) + 0.5) / height * (hi[1] - lo[1]), indexing="xy")
    P = np.stack([X.ravel(), Y.ravel(), np.full(X.size, depth)], -1)
    L = light_points(sc64.lights.source(0), P, scene_size(V, P), np.float32).points
    dtype = "float32" if "float32" in cfg.dtypes else cfg.dtypes[0]
    out = []
    for row in rows:
        if row["config"] not in FRAME_CONFIGS or row["dtype"] != dtype:
            continue
        method, opts = CONFIGS[row["config"]]
        with precision(row["dtype"]):
            mesh = sc64.surface.astype(row["dtype"])
            Pd, Ld = np.asarray(P, row["dtype"]), np.asarray(L, row["dtype"])
            _, _, steady, _ = _timed(lambda m=method, o=opts, x=mesh, p=Pd, l_=Ld:  # noqa: E731
                                     solve(x, p, l_, eta=cfg.eta, method=m, **o), 1)
        out.append({"config": row["config"], "dtype": row["dtype"], "width": width, "height": height,
                    "seconds": steady, "compile_s": row["compile_s"], "compile_cached": row["compile_cached"]})
        log(f"[{row['dtype']}] {row['config']}: a {width}x{height} frame in {steady * 1e3:.0f} ms")
    return out


def _rank(row: dict):
    return (row["success"] if row["success"] is not None else row["found"], row["solves_per_s"])


def ratios(report: dict) -> list[dict]:
    """Walk throughput over the best Newton configuration (best success, then speed), per dtype."""
    out = []
    for dtype in {r["dtype"] for r in report["rows"]}:
        rows = [r for r in report["rows"] if r["dtype"] == dtype]
        walk = [r for r in rows if r["config"] == "walk"]
        newton = [r for r in rows if r["method"] == "newton"]
        if not walk or not newton:
            continue
        best = max(newton, key=_rank)
        out.append({"dtype": dtype, "best_newton": best["config"],
                    "speed_ratio": walk[0]["solves_per_s"] / best["solves_per_s"],
                    "walk_success": walk[0]["success"], "newton_success": best["success"]})
    return sorted(out, key=lambda r: r["dtype"])

