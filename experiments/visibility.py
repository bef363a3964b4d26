# %% [markdown]
# # Visibility (seed 001 §4): how much light does the surface itself block?
#
# `irradiance(..., visibility=True)` drops a path `P -> M -> L` whose segment `M -> L` or
# `P -> M` crosses the water surface anywhere but at `M` (`transport/visibility.py`). How
# much of the caustic irradiance does that remove, on steep waves and under grazing light,
# and what does the test cost? Per scene: the all-path irradiance (certified reference,
# float64) and the walk's one-path irradiance with and without visibility, over 256
# receivers on the floor; the fraction of the total removed, the fraction of paths
# blocked, and the time of the walk's irradiance with and without the test (same process,
# interleaved; the machine's 2 cores are shared).
#
# Run: `python -m experiments.visibility` (writes `figures/visibility.json`, prints a table).

# %%
from __future__ import annotations

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import caustics_jax as cj  # noqa: E402
from caustics_jax import scenes  # noqa: E402
from caustics_jax.transport import irradiance, path_visible  # noqa: E402
from experiments.common import figures_dir, parse_args, write_json  # noqa: E402

UP = [0.0, 0.0, 1.0]


def light_at(elevation_deg: float, distance: float = 6.0):
    e = np.radians(elevation_deg)
    return (distance * np.cos(e), 0.0, distance * np.sin(e))


# name: (wavy_pool keyword arguments)
SCENES = {
    "gentle, light 72 deg up": dict(amplitude=0.03, light_position=(0.4, -0.3, 3.0)),
    "steep (0.1 m, 0.6 m waves), light 72 deg up": dict(amplitude=0.1, n_waves=1, wavelength=(0.6, 0.6),
                                                        light_position=(0.4, -0.3, 3.0)),
    "steep, light 30 deg up": dict(amplitude=0.1, n_waves=1, wavelength=(0.6, 0.6), light_position=light_at(30)),
    "steep, light 15 deg up": dict(amplitude=0.1, n_waves=1, wavelength=(0.6, 0.6), light_position=light_at(15)),
    "gentle, light 10 deg up": dict(amplitude=0.03, light_position=light_at(10)),
    "gentle, light 5 deg up": dict(amplitude=0.03, light_position=light_at(5)),
}


def measure(name: str, kwargs: dict, n_side: int, repeats: int = 3) -> dict:
    with cj.precision("float64"):
        sc = scenes.wavy_pool(2048, n_receivers=n_side, dtype="float64", **kwargs)
        mesh, P = sc.surface, np.asarray(sc.receivers)
        L = np.asarray(sc.lights.endpoint(P))
        kw = dict(intensity=1.0, receiver_normal=UP)
        ref = cj.solve(mesh, P, L, method="exhaustive", return_all=True)
        E_all = np.asarray(irradiance(mesh, P, L, method="exhaustive", all_paths=True, **kw))
        E_all_vis = np.asarray(irradiance(mesh, P, L, method="exhaustive", all_paths=True, visibility=True, **kw))
        valid = np.arange(ref.all_points.shape[1])[None] < ref.count[:, None]
        lane, k = np.nonzero(valid)
        visible = path_visible(mesh, P[lane], ref.all_points[lane, k], L[lane])
        times = {False: [], True: []}
        E_walk = {}
        for vis in (False, True):  # compile
            E, sol = irradiance(mesh, P, L, method="walk", visibility=vis, return_solution=True, **kw)
            E_walk[vis] = np.asarray(E)
            if not vis:
                walk_found, walk_status = int(np.sum(np.asarray(sol.found))), sol.summary()
        for _ in range(repeats):
            for vis in (False, True):
                t = time.perf_counter()
                jax.block_until_ready(irradiance(mesh, P, L, method="walk", visibility=vis, **kw))
                times[vis].append(time.perf_counter() - t)
    total = max(E_all.sum(), 1e-300)
    return {
        "scene": name, "receivers": len(P), "paths": int(len(lane)), "paths_blocked": int((~visible).sum()),
        "removed_all_paths": float(1 - E_all_vis.sum() / total),
        "receivers_losing_light": int(np.sum(E_all_vis < E_all * (1 - 1e-12))),
        # None where the walk finds no path at all (nothing to remove; 0/0 is not 100%).
        "walk_found": walk_found, "walk_status": walk_status,
        "walk_share_of_all_paths": float(E_walk[False].sum() / total),
        "removed_walk": float(1 - E_walk[True].sum() / E_walk[False].sum()) if E_walk[False].sum() > 0 else None,
        "walk_ms": 1e3 * float(np.median(times[False])), "walk_visibility_ms": 1e3 * float(np.median(times[True])),
    }


def table(rows) -> str:
    lines = ["| scene | paths (all, per receivers) | paths blocked | all-path irradiance removed "
             "| walk: lanes found, share of all-path irradiance | walk's removed "
             "| walk irradiance ms: without / with visibility |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        walk = "-" if r["removed_walk"] is None else f"{100 * r['removed_walk']:.2f}%"
        share = 100 * r["walk_share_of_all_paths"]
        lines.append(f"| {r['scene']} | {r['paths']} / {r['receivers']} | {r['paths_blocked']} "
                     f"| {100 * r['removed_all_paths']:.2f}% | {r['walk_found']}, {share:.1f}% "
                     f"| {walk} | {r['walk_ms']:.0f} / {r['walk_visibility_ms']:.0f} |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="64 receivers per scene")
    args = parse_args(ap, argv)
    n_side = 8 if args.quick else 16
    t0 = time.time()
    rows = [measure(name, kw, n_side) for name, kw in SCENES.items()]
    write_json(figures_dir() / "visibility.json", dict(rows=rows, seconds=time.time() - t0))
    print(table(rows))
    print(f"wrote figures/visibility.json ({time.time() - t0:.0f} s)")


if __name__ == "__main__":
    main()
