# %% [markdown]
# # Caustic irradiance three ways: walk + D, photon differentials, brute-force photons
#
# Question: does the irradiance of a solved path, `E = eta^2 T cos(theta_P) I_e / D`
# (seed 001 eq. 25-33 with the factors of math.md §6), agree with forward light transport?
#
# - (a) walk + D: `caustics_jax.irradiance` at 3 x 3 midpoints per receiver cell, averaged;
# - (b) photon differentials: photons on a 512^2 light-view texel grid, each with its exact
#   Jacobian (`texel_jacobian`), splatted as flux-conserving anisotropic Gaussians
#   (seed 003 footprints); also their pointwise irradiance at the landing point;
# - (c) brute-force photons binned on the receiver cells (`photon_irradiance`), 2^20 to 2^26.
#
# Scenes: the flat pool (an exact formula, `testing.flat_interface_irradiance`), the
# wavy pool (8192 triangles, amplitude 0.1, floor 1 m deep: pre-focal, every receiver
# has one path) and, past the focal distance, a steep pool 3 m deep where several paths
# reach one receiver (walk vs the sum over all exhaustive solutions vs photons along a
# transect). Last, the error of seed 004's same-t' compression ratio.
#
# Run: `python -m experiments.irradiance_agreement [--quick]`; writes
# `figures/irradiance_agreement.png`, `figures/irradiance_postfocal.png` and
# `figures/irradiance_agreement.json`.

# %%
from __future__ import annotations

import argparse
import json
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from caustics_jax import (  # noqa: E402
    barycentric_point,
    interpolated_normal,
    refract,
    safe_normalize,
    scenes,  # noqa: E402
)
from caustics_jax.solvers import solve  # noqa: E402
from caustics_jax.testing import flat_interface_irradiance  # noqa: E402
from caustics_jax.transport import (  # noqa: E402
    ReceiverGrid,
    compression_ratio,
    compression_ratio_exact,
    irradiance,
    path_irradiance,
    photon_differential_irradiance,
    photon_irradiance,
    splat_footprints,
    texel_jacobian,
    triangle_area,
)
from caustics_jax.transport.photon_differentials import light_view_texels  # noqa: E402
from experiments.common import ROOT, parse_args, stats, use_agg, write_json  # noqa: E402

LIGHT = np.array([0.4, -0.3, 3.0])
UP = np.array([0.0, 0.0, 1.0])
ETA = 1.333
FIG = ROOT / "figures"


def walk_map(mesh, receiver, k=3, dtype=jnp.float64):
    """(a): the cell average of walk + D irradiance by the k x k midpoint rule."""
    P = jnp.asarray(receiver.subsamples(k).reshape(-1, 3), dtype)
    E, sol = irradiance(mesh.astype(dtype), P, jnp.asarray(LIGHT, dtype), intensity=1.0, eta=ETA,
                        receiver_normal=UP, return_solution=True)
    return np.asarray(E, np.float64).reshape(receiver.ny, receiver.nx, k * k).mean(-1), sol.summary()


def texel_photons(mesh, res, depth):
    """(b) inputs: light-view texels, their landing points, flux and exact Jacobians."""
    tx = light_view_texels(mesh, LIGHT, res)
    V, N = mesh.triangle(tx.face)
    L = jnp.asarray(LIGHT)
    rp, rn = jnp.asarray([0, 0, -depth]), jnp.asarray(UP)
    J, Y, T, cos_e, r_e, t, ok = texel_jacobian(V, N, L, tx.X, ETA, rp, rn)
    E_pd, _, ok_e = photon_differential_irradiance(V, N, L, tx.X, ETA, 1.0, rp, rn)
    ok = np.asarray(ok & tx.found)
    # Flux through one texel: I_e cos_e du dv / r_e^2 (photons.py), times T.
    flux = np.asarray(T * cos_e / r_e**2) * tx.du * tx.dv
    return dict(tx=tx, V=V, N=N, J=np.asarray(J), Y=np.asarray(Y), flux=flux, ok=ok, E_pd=np.asarray(E_pd),
                ok_e=np.asarray(ok_e))


def pd_map(ph, receiver):
    ok = ph["ok"].reshape(-1)
    return splat_footprints(jnp.asarray(ph["Y"].reshape(-1, 3)[ok, :2]), jnp.asarray(ph["flux"].reshape(-1)[ok]),
                            ph["J"].reshape(-1, 2, 2)[ok], ph["tx"].du, ph["tx"].dv, receiver)


def errors(E, ref):
    mask = ref > 0
    return dict(rel_L1=float(np.sum(np.abs(E - ref)[mask]) / np.sum(ref[mask])),
                rel_max=float(np.max(np.abs(E - ref)[mask] / ref[mask])))


# %%
def flat_check(quick):
    """Flat pool: (a), (b) pointwise and (c) against the exact formula."""
    scene = scenes.flat_pool(8192, dtype=jnp.float64)
    receiver = ReceiverGrid(-1.0, -1.6, 1.6, -1.6, 1.6, 32, 32)
    k = 3
    exact = flat_interface_irradiance(receiver.subsamples(k).reshape(-1, 3), LIGHT, 0.0, ETA)
    exact = exact.reshape(receiver.ny, receiver.nx, k * k).mean(-1)
    Ea, _ = walk_map(scene.surface, receiver, k)
    ph = texel_photons(scene.surface, 128, 1.0)
    good = ph["ok_e"]
    pts = ph["Y"][good]
    E_pts = flat_interface_irradiance(pts, LIGHT, 0.0, ETA)
    pm = photon_irradiance(scene.surface, LIGHT, intensity=1.0, eta=ETA, receiver=receiver,
                           n_photons=1 << (20 if quick else 24), seed=0, chunk=1 << 18)
    z = (pm.irradiance - exact) / pm.stderr
    return dict(walk=errors(Ea, exact),
                photon_differential_pointwise_max_rel=float(np.max(np.abs(ph["E_pd"][good] / E_pts - 1))),
                photons=dict(n=pm.n_photons, **errors(pm.irradiance, exact), mean_z2=float(np.mean(z**2))))


# %%
def wavy_agreement(quick, amplitude=0.1):
    scene = scenes.wavy_pool(8192, amplitude=amplitude, dtype=jnp.float64)
    mesh = scene.surface
    receiver = ReceiverGrid(-1.0, -1.6, 1.6, -1.6, 1.6, 64, 64)
    t0 = time.perf_counter()
    Ea, status = walk_map(mesh, receiver)
    t_walk = time.perf_counter() - t0
    Ea32, _ = walk_map(mesh, receiver, dtype=jnp.float32)
    t0 = time.perf_counter()
    ph = texel_photons(mesh, 256 if quick else 512, 1.0)
    Eb = pd_map(ph, receiver)
    t_pd = time.perf_counter() - t0
    # Pointwise: forward photon differential vs backward walk + D at the same landing point.
    good = ph["ok_e"] & ph["ok"]
    tx = ph["tx"]
    L = jnp.asarray(LIGHT)
    Yg = jnp.asarray(ph["Y"][good])
    E_back, ok_b = path_irradiance(ph["V"][good], ph["N"][good], Yg, jnp.broadcast_to(L, Yg.shape),
                                   tx.ab[good], ETA, 1.0, jnp.asarray(UP))
    rel_fb = np.abs(ph["E_pd"][good] / np.asarray(E_back) - 1)[np.asarray(ok_b)]
    rows = []
    maps = {}
    for p in ([20, 22] if quick else [20, 22, 24, 26]):
        t0 = time.perf_counter()
        pm = photon_irradiance(mesh, LIGHT, intensity=1.0, eta=ETA, receiver=receiver, n_photons=1 << p,
                               seed=p, chunk=1 << 18)
        dt = time.perf_counter() - t0
        z = (pm.irradiance - Ea) / pm.stderr
        rows.append(dict(n=pm.n_photons, seconds=dt, **errors(pm.irradiance, Ea),
                         median_rel_stderr=float(np.median(pm.stderr / Ea)), mean_z2=float(np.mean(z**2)),
                         max_abs_z=float(np.max(np.abs(z)))))
        maps["photons"], maps["stderr"] = pm.irradiance, pm.stderr
        print(f"  photons 2^{p}: rel L1 {rows[-1]['rel_L1']:.2e}, max {rows[-1]['rel_max']:.2e}, "
              f"mean z^2 {rows[-1]['mean_z2']:.2f} ({dt:.0f} s)")
    maps.update(walk=Ea, pd=Eb)
    return dict(scene=scene.name, receiver=receiver._asdict(), walk_status=status, walk_seconds=t_walk,
                pd_seconds=t_pd, pd_texels=int(tx.X.shape[0] ** 2),
                walk_float32_vs_float64=errors(Ea32, Ea), pd_map_vs_walk=errors(Eb, Ea),
                forward_vs_backward_pointwise=dict(median=float(np.median(rel_fb)),
                                                   p99=float(np.percentile(rel_fb, 99)),
                                                   max=float(np.max(rel_fb)), n=int(rel_fb.size)),
                photons=rows), maps


# %%
def postfocal(quick):
    """Past the focal distance: a transect of the floor 3 m down under steep waves (2048 triangles).

    The transect runs along x at the y where most folded photons land (texels whose
    Jacobian determinant is negative lie on a fold of the light-view map: there the
    receiver is reached by several paths). 3 m down the light spreads past the pool walls,
    so the floor is taken as an unbounded plane. Walk and exhaustive values are cell
    averages over k x k midpoints, like the photon bins.
    """
    depth = 3.0
    scene = scenes.wavy_pool(2048, amplitude=0.3, depth=depth, dtype=jnp.float64)
    mesh = scene.surface
    ph = texel_photons(mesh, 128, depth)
    folded = (np.linalg.det(ph["J"]) < 0) & ph["ok"]
    y_fold = ph["Y"][folded][:, 1]
    hist, edges = np.histogram(y_fold, bins=40, range=(-5, 5))
    y0 = 0.5 * (edges[np.argmax(hist)] + edges[np.argmax(hist) + 1])
    n, k = (60, 2) if quick else (160, 4)
    receiver = ReceiverGrid(-depth, -4.0, 2.0, y0 - 0.02, y0 + 0.02, n, 1)
    P = receiver.subsamples(k).reshape(-1, 3)
    Pj, L = jnp.asarray(P), jnp.asarray(LIGHT)
    cell = lambda E: np.asarray(E).reshape(n, k * k).mean(-1)  # noqa: E731
    walk = cell(irradiance(mesh, Pj, L, intensity=1.0, eta=ETA, receiver_normal=UP))
    res = solve(mesh, Pj, jnp.broadcast_to(L, Pj.shape), eta=ETA, method="exhaustive", return_all=True)
    total = cell(irradiance(mesh, Pj, L, intensity=1.0, eta=ETA, receiver_normal=UP, method="exhaustive",
                            all_paths=True))
    pm = photon_irradiance(mesh, LIGHT, intensity=1.0, eta=ETA, receiver=receiver,
                           n_photons=1 << (22 if quick else 26), seed=11, chunk=1 << 18)
    count = np.asarray(res.count).reshape(n, k * k).max(-1)
    multi, single = count > 1, count == 1
    se = np.where(pm.stderr[0] > 0, pm.stderr[0], np.inf)
    z_total = (pm.irradiance[0] - total) / se
    z_walk = (pm.irradiance[0] - walk) / se

    def within(z, mask):
        return float(np.mean(np.abs(z[mask]) < 3)) if mask.any() else None

    return dict(y=float(y0), count=count.tolist(), x=receiver.centers()[0, :, 0].tolist(), walk=walk.tolist(),
                total=total.tolist(), photons=pm.irradiance[0].tolist(), stderr=pm.stderr[0].tolist(),
                within_3se_total_single=within(z_total, single), within_3se_total_multi=within(z_total, multi),
                within_3se_walk_multi=within(z_walk, multi),
                walk_share_multi=float(np.median(walk[multi] / total[multi])) if multi.any() else None,
                lanes_multi=int(multi.sum()), lanes_single=int(single.sum()), n_photons=pm.n_photons)


# %%
def same_t_error(quick):
    """Seed 004 Alg. 2 (same t') against the exact receiver triangle and the Jacobian."""
    scene = scenes.wavy_pool(8192, amplitude=0.1, dtype=jnp.float64)
    mesh, L = scene.surface, jnp.asarray(LIGHT)
    rp, rn = jnp.asarray([0, 0, -1.0]), jnp.asarray(UP)
    out = []
    for res in ([64, 256] if quick else [64, 256, 1024]):
        tx = light_view_texels(mesh, LIGHT, res)
        V, N = mesh.triangle(tx.face)
        M = barycentric_point(V, tx.ab)
        n_s = safe_normalize(interpolated_normal(N, tx.ab))
        l_dir = safe_normalize(M - L)
        J, Y, T, cos_e, r_e, t, ok = texel_jacobian(V, N, L, tx.X, ETA, rp, rn)
        head, tail = slice(None, -1), slice(1, None)
        c, r, u = (head, head), (head, tail), (tail, head)  # x00, x10 (right), x01 (up)
        x00, x10, x01 = M[c], M[r], M[u]
        n00, n10, n01 = n_s[c], n_s[r], n_s[u]
        l00, l10, l01 = l_dir[c], l_dir[r], l_dir[u]
        t00 = t[c]
        w00 = refract(l00, n00, 1 / ETA)
        a = 1 / -w00[..., 2]  # seed 004 eq. 18: foreshortening on the receiver (normal +z)
        sig_alg2, _ = compression_ratio(x00, x10, x01, n00, n10, n01, l00, t00, eta=ETA)
        sig_pl, _ = compression_ratio(x00, x10, x01, n00, n10, n01, l00, t00, eta=ETA, l_dir10=l10, l_dir01=l01)
        exact, ok_x = compression_ratio_exact(x00, x10, x01, n00, n10, n01, l00, rp, rn, eta=ETA,
                                              l_dir10=l10, l_dir01=l01)
        A = triangle_area(x00, x10, x01)
        A = np.asarray(A)
        jac = np.abs(np.linalg.det(np.asarray(J[c]))) * tx.du * tx.dv / 2 / np.where(A > 0, A, 1)
        found = np.asarray(tx.found)
        good = found[c] & found[r] & found[u] & np.asarray(ok[c] & ok_x)

        def stat(num, den, good=good):
            return stats(np.abs(np.asarray(num)[good] / np.asarray(den)[good] - 1))

        ex = np.asarray(exact)
        out.append(dict(res=res, texel_m=tx.du,
                        alg2_single_ldir_times_a=stat(np.asarray(sig_alg2) ** 2 * np.asarray(a), ex),
                        same_t_per_neighbour_times_a=stat(np.asarray(sig_pl) ** 2 * np.asarray(a), ex),
                        same_t_per_neighbour=stat(np.asarray(sig_pl) ** 2, ex),
                        exact_triangle_vs_jacobian=stat(ex, jac)))
    return out


# %%
def plot(wavy, maps, post, path_main, path_post):
    use_agg()
    import matplotlib.pyplot as plt

    rec = ReceiverGrid(**wavy["receiver"])
    ext = (rec.x0, rec.x1, rec.y0, rec.y1)
    fig, axes = plt.subplots(2, 4, figsize=(19, 9.2))
    vmin, vmax = np.percentile(maps["walk"], [0.5, 99.5])
    n_max = wavy["photons"][-1]["n"]
    res = int(round(np.sqrt(wavy["pd_texels"])))
    titles = [("walk", "(a) walk + D, cell averages"),
              ("pd", f"(b) photon differentials, {res}² texels"),
              ("photons", f"(c) brute-force photons, N = 2^{int(np.log2(n_max))}")]
    for ax, (key, title) in zip(axes[0, :3], titles, strict=True):
        im = ax.imshow(maps[key], origin="lower", extent=ext, vmin=vmin, vmax=vmax, cmap="inferno")
        ax.set_title(title, fontsize=10)
        ax.set(xlabel="x (m)", ylabel="y (m)")
        fig.colorbar(im, ax=ax, label="irradiance (W/m², I_e = 1 W/sr)", shrink=0.85)
    for ax, key, title in ((axes[1, 0], "pd", "(b) / (a) - 1"), (axes[1, 1], "photons", "(c) / (a) - 1")):
        rel = maps[key] / maps["walk"] - 1
        lim = np.percentile(np.abs(rel), 99.5)
        im = ax.imshow(rel, origin="lower", extent=ext, vmin=-lim, vmax=lim, cmap="RdBu_r")
        ax.set_title(title, fontsize=10)
        ax.set(xlabel="x (m)", ylabel="y (m)")
        fig.colorbar(im, ax=ax, label="relative difference", shrink=0.85)
    z = (maps["photons"] - maps["walk"]) / maps["stderr"]
    ax = axes[1, 2]
    ax.hist(z.ravel(), bins=60, density=True, color="C0", alpha=0.7, label="cells")
    g = np.linspace(-4.5, 4.5, 200)
    ax.plot(g, np.exp(-g**2 / 2) / np.sqrt(2 * np.pi), "k--", label="standard normal")
    ax.set(title="((c) - (a)) / photon standard error", xlabel="z-score", ylabel="density")
    ax.legend(fontsize=8)
    ax = axes[0, 3]
    n = np.array([r["n"] for r in wavy["photons"]])
    ax.loglog(n, [r["rel_L1"] for r in wavy["photons"]], "o-", label="(c) vs (a): relative L1")
    ax.loglog(n, [r["median_rel_stderr"] for r in wavy["photons"]], "s--", label="(c): median relative std. error")
    ax.loglog(n, wavy["photons"][0]["rel_L1"] * np.sqrt(n[0] / n), "k:", label="∝ 1/√N")
    ax.axhline(wavy["pd_map_vs_walk"]["rel_L1"], color="C2", label="(b) vs (a): relative L1")
    ax.set(title="Error against photon count", xlabel="photons N", ylabel="relative error")
    ax.legend(fontsize=8, loc="upper right")
    ax.set_ylim(5e-4, 0.3)
    ax.grid(True, which="both", alpha=0.3)
    axes[1, 3].axis("off")
    fb = wavy["forward_vs_backward_pointwise"]
    lines = ["wavy_pool: 8192 triangles, amplitude 0.1 m", "floor 1 m deep, 64 x 64 cells of 5 cm",
             "light (0.4, -0.3, 3) m, eta 1.333", "",
             f"(b) vs (a): rel L1 {wavy['pd_map_vs_walk']['rel_L1']:.1e}, max {wavy['pd_map_vs_walk']['rel_max']:.1e}",
             f"(c) vs (a), N = 2^{int(np.log2(n_max))}: rel L1 {wavy['photons'][-1]['rel_L1']:.1e}, "
             f"mean z² {wavy['photons'][-1]['mean_z2']:.2f}",
             f"walk float32 vs float64: rel max {wavy['walk_float32_vs_float64']['rel_max']:.1e}",
             "pointwise forward (photon differential)",
             "  vs backward (walk + D):",
             f"  median {fb['median']:.1e}, max {fb['max']:.1e}",
             "  (Phong normals are not reciprocal: O(h))"]
    axes[1, 3].text(0, 1, "\n".join(lines), va="top", family="monospace", fontsize=8.5)
    fig.suptitle("Caustic irradiance on the floor of a wavy pool: walk + D (seed 001 eq. 25-33) against "
                 "photon differentials (seeds 003/004) and brute-force photons", fontsize=12)
    fig.tight_layout()
    fig.savefig(path_main, dpi=110)
    plt.close(fig)

    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(11, 7), sharex=True, gridspec_kw=dict(height_ratios=[3, 1]))
    x = np.array(post["x"])
    ax.errorbar(x, post["photons"], yerr=2 * np.array(post["stderr"]), fmt=".", color="0.5", ms=4,
                label=f"brute-force photons (2^{int(np.log2(post['n_photons']))}, ±2 s.e.)")
    ax.plot(x, post["total"], "-", color="C3", label="sum over all exhaustive solutions")
    ax.plot(x, post["walk"], "--", color="C0", label="walk + D (one path)")
    ax.set(ylabel="irradiance (W/m², I_e = 1 W/sr)",
           title="Past the focal distance (floor 3 m deep, steep waves): one path is not the whole irradiance")
    ax.legend(fontsize=9)
    ax.grid(True, alpha=0.3)
    ax2.step(x, post["count"], where="mid", color="k")
    ax2.set(xlabel=f"x on the transect y = {post['y']:.2f} m (m)", ylabel="paths")
    ax2.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path_post, dpi=110)
    plt.close(fig)


# %%
def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="fewer photons and texels (about two minutes)")
    ap.add_argument("--replot", action="store_true", help="redraw the figures from the saved JSON and maps")
    args = parse_args(ap, argv)
    if args.replot:
        out = json.loads((FIG / "irradiance_agreement.json").read_text())
        maps = dict(np.load(FIG / "irradiance_agreement_maps.npz"))
        plot(out["wavy"], maps, out["postfocal"], FIG / "irradiance_agreement.png", FIG / "irradiance_postfocal.png")
        return
    t0 = time.perf_counter()
    print("flat pool against the exact formula ...")
    flat = flat_check(args.quick)
    print(f"  walk rel max {flat['walk']['rel_max']:.1e}; photon differential pointwise max "
          f"{flat['photon_differential_pointwise_max_rel']:.1e}; photons rel L1 {flat['photons']['rel_L1']:.1e}, "
          f"mean z^2 {flat['photons']['mean_z2']:.2f}")
    print("wavy pool (pre-focal) ...")
    wavy, maps = wavy_agreement(args.quick)
    print(f"  (b) vs (a) rel L1 {wavy['pd_map_vs_walk']['rel_L1']:.2e}; forward vs backward pointwise median "
          f"{wavy['forward_vs_backward_pointwise']['median']:.1e}")
    print("default wavy pool (amplitude 0.03) ...")
    default, _ = wavy_agreement(True, amplitude=0.03)
    print("past the focal distance ...")
    post = postfocal(args.quick)
    print(f"  {post['lanes_multi']} cells with several paths: photons within 3 s.e. of the sum "
          f"{post['within_3se_total_multi']}, of the walk's one path {post['within_3se_walk_multi']} "
          f"(walk / sum median {post['walk_share_multi']}); single-path cells within 3 s.e. "
          f"{post['within_3se_total_single']}")
    print("same-t' shortcut ...")
    same_t = same_t_error(args.quick)
    for r in same_t:
        print(f"  res {r['res']}: Alg. 2 median {r['alg2_single_ldir_times_a']['median']:.3f}, per-neighbour "
              f"{r['same_t_per_neighbour_times_a']['median']:.3f}, "
              f"without a {r['same_t_per_neighbour']['median']:.3f}, "
              f"exact triangle vs Jacobian {r['exact_triangle_vs_jacobian']['median']:.1e}")
    out = dict(flat=flat, wavy=wavy, default_wavy=default, postfocal=post, same_t=same_t,
               seconds=time.perf_counter() - t0, quick=args.quick)
    write_json(FIG / "irradiance_agreement.json", out)
    np.savez_compressed(FIG / "irradiance_agreement_maps.npz", **{k: v.astype(np.float32) for k, v in maps.items()})
    plot(wavy, maps, post, FIG / "irradiance_agreement.png", FIG / "irradiance_postfocal.png")
    print(f"wrote figures/irradiance_agreement.png, irradiance_postfocal.png, .json ({out['seconds']:.0f} s)")


if __name__ == "__main__":
    main()
