# %% [markdown]
# # The coplanarity curve across a wavy mesh (seed 001 Fig. 3)
#
# Question: what does the set of points `M` with `n~(a, b) . (PL x PM) = 0` (seed 001
# eq. 9-12, math.md §2) look like on a small wavy water surface, and does the curve walk
# (`caustics_jax.solve`) really travel along it from the start point `M0 = PL ∩ surface`
# to the refraction point `M`?
#
# The curve is traced by the library, in float64: `caustics_jax.curve.arcs.trace_arcs` cuts each
# face's conic by its edges (seed 001 eq. 22-24) and samples every arc inside the face
# through the pencil of lines through its start root (`arcs.face_arcs`, `FaceArcs.point`),
# vmapped over all faces: the same parametrisation the walk refines on and the exhaustive
# reference scans. Each sample is checked independently of the conic code by the numpy
# oracle's triple product (`testing.oracle.triple_product`, eq. 9). Arcs are chained across
# shared edges into connected components (figure logic, below); along the component through
# `M0` the objective the solvers bracket (`objectives.bracket_objective`: the signed sine `f`
# of eq. 19-21 in the "plane" orientation) is evaluated, and its roots on every component
# (a sign change in both orientations, `arcs.root_between`) form an independent
# all-solutions check of the walk's `M`.
#
# Run: `python -m experiments.conic_curve` (writes `figures/conic_curve.png` and `.json`,
# prints a table). Also `make figures`.

# %%
from __future__ import annotations

import functools
import time

import jax
import jax.numpy as jnp
import numpy as np

import caustics_jax as cj
from caustics_jax.curve.arcs import N_ARCS, root_between, trace_arcs
from caustics_jax.math.objectives import ObjectiveStatus, bracket_objective
from caustics_jax.surface.scenes import wavy_pool
from caustics_jax.testing import oracle
from experiments.common import figures_dir, log, use_agg, write_json

use_agg()
import matplotlib  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.tri  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402

FIG = figures_dir() / "conic_curve.png"

# A 14 x 14 cell heightfield (392 triangles) over a 2.1 m square, |z| <= 10 cm, wavelengths
# 0.5-1.2 m (3-8 cells): a curve that visibly bends, still resolved by the mesh.
SCENE = dict(n_triangles=392, seed=3, amplitude=0.1, wavelength=(0.5, 1.2), half_size=1.0)
P_RECEIVER = (-0.6, -0.5, -0.6)  # under the water (m)
L_LIGHT = (0.8, 0.6, 1.0)  # above it (m)
ETA = 1.333
# Pencil samples per arc, uniform in the pencil angle: 256 keeps consecutive samples within
# about 1 mm on this mesh (the JSON records the largest spacing).
SAMPLES = 256
INSIDE_TOL = 1e-12  # barycentric slack of the inside-the-face check of the samples
MATCH_TOL = 1e-9  # arcs of neighbouring faces join when their ends are this close (m)


# %% [markdown]
# ## Tracing the conic inside each face (the library tracer)


# %%
@functools.partial(jax.jit, static_argnames="samples")
def _trace(V, N, P, L, samples):
    return trace_arcs(V, N, P, L, samples, return_arcs=True)


def trace_curve(V, N, P, L, samples=SAMPLES):
    """Every arc of the coplanarity curve on the faces `V, N` `(F, 3, 3)`, each once.

    Returns a list of dicts (face, ab `(samples, 2)`, xyz `(samples, 3)`, closed) and the
    conic coefficients `(F, 6)`. `face_arcs` lists an arc from each of its two end roots
    (each oriented inward); the copy that starts at the lower root slot is kept. An
    ellipse inside its face (the last slot) is kept when its anchor lies in the face.
    """
    ab, _, _, arcs = (jax.tree.map(np.asarray, x) for x in _trace(V, N, P, L, samples))
    V = np.asarray(V)
    exists = arcs.ok & oracle.inside_triangle(arcs.starts, INSIDE_TOL)
    out = []
    for f, k in zip(*np.nonzero(exists), strict=True):
        closed = k == N_ARCS - 1
        if not closed:
            # the slot of the root this arc ends on: ends are copies of the root values
            twin = np.nonzero(np.all(arcs.starts[f, : N_ARCS - 1] == arcs.ends[f, k], -1))[0]
            if len(twin) and twin[0] < k and exists[f, twin[0]]:
                continue
        # The ends are the exact edge roots: at u = 0 the pencil line is the conic's
        # tangent, whose second intersection is a double root split by rounding (off the
        # start along the curve by up to 2e-7 in float64, `trace_arcs`), and arcs of
        # neighbouring faces must meet.
        ab_k = ab[f, k].copy()
        ab_k[0], ab_k[-1] = arcs.starts[f, k], arcs.ends[f, k]
        out.append(dict(face=int(f), ab=ab_k, xyz=oracle.barycentric_point(V[f], ab_k), closed=bool(closed)))
    return out, arcs.coef


# %% [markdown]
# ## Chaining arcs into connected curves


# %%
def components(arcs):
    """Group arcs into connected components by matching end points (world, `MATCH_TOL`).

    Returns a list of components, each a list of `(arc index, reversed)` in curve order,
    plus the largest end-point mismatch among joined ends (continuity across edges).
    """
    ends = np.array([[a["xyz"][0], a["xyz"][-1]] for a in arcs])  # (n, 2, 3)
    flat = ends.reshape(-1, 3)
    dist = np.linalg.norm(flat[:, None] - flat[None], axis=-1)
    np.fill_diagonal(dist, np.inf)
    for i in range(len(arcs)):  # an arc's own two ends never join each other here
        dist[2 * i, 2 * i + 1] = dist[2 * i + 1, 2 * i] = np.inf
    partner = np.where(dist.min(1) < MATCH_TOL, dist.argmin(1), -1)
    joined = dist.min(1)[partner >= 0]
    seen, comps = set(), []
    for start in range(len(arcs)):
        if start in seen:
            continue
        # go backwards from `start` to an open end (or around a loop), then forwards
        i, rev = start, False
        for _ in range(len(arcs)):
            p = partner[2 * i + (1 if rev else 0)]  # the end we arrived through
            if p < 0 or p // 2 == start:
                break
            i, rev = p // 2, p % 2 == 0  # entered through its start -> walk it reversed
        chain = []
        while i not in seen:
            seen.add(i)
            chain.append((i, rev))
            p = partner[2 * i + (0 if rev else 1)]  # the end we leave through
            if p < 0:
                break
            i, rev = p // 2, p % 2 == 1
        comps.append(chain)
    return comps, float(joined.max(initial=0.0))


def polyline(arcs, chain):
    """Concatenated `(xyz, face, ab)` along a chain (joined end points counted once)."""
    xyz, face, ab = [], [], []
    for k, (i, rev) in enumerate(chain):
        s = slice(None, None, -1) if rev else slice(None)
        skip = 1 if k else 0
        xyz.append(arcs[i]["xyz"][s][skip:])
        ab.append(arcs[i]["ab"][s][skip:])
        face.append(np.full(len(ab[-1]), arcs[i]["face"]))
    return np.concatenate(xyz), np.concatenate(face), np.concatenate(ab)


def distance_to_polyline(q, xyz, s=None):
    """Distance from `q` to the polyline `xyz`; with arc lengths `s` at its vertices, also
    the arc length of the nearest point."""
    a, b = xyz[:-1], xyz[1:]
    d = b - a
    t = np.clip(np.sum((q - a) * d, -1) / np.maximum(np.sum(d * d, -1), 1e-300), 0, 1)
    dist = np.linalg.norm(a + t[:, None] * d - q, axis=-1)
    i = int(np.argmin(dist))
    if s is None:
        return float(dist[i])
    return float(dist[i]), float(s[i] + t[i] * (s[i + 1] - s[i]))


# %%
@functools.partial(jax.jit, static_argnames="eta")
def _bracket_objective(V, N, P, L, ab, eta):
    """`(f, status, g)` of `objectives.bracket_objective` at one point per triangle."""
    return jax.vmap(lambda v, n, x: tuple(y[0] for y in bracket_objective(v, n, P, L, x[None], eta)))(V, N, ab)


def curve_roots(f, g, status, s):
    """Brackets `(s_lo, s_hi)` of the roots of `f` along one component: a sign change in
    both orientations between consecutive samples (`arcs.root_between`, as the walk and the
    exhaustive reference judge it), both samples with status OK."""
    ok = (status[:-1] == ObjectiveStatus.OK) & (status[1:] == ObjectiveStatus.OK)
    flip = np.asarray(root_between((f[:-1], g[:-1]), (f[1:], g[1:]))) & ok
    i = np.nonzero(flip)[0]
    return np.stack([s[i], s[i + 1]], -1)


def distance_to_conic(coef, ab, V):
    """First-order world distance `|Q| / |grad_world Q|` from `ab` to the conic `coef` of
    face `V` (the gradient of `conic.conic_value` by autodiff, mapped to the face's plane)."""
    Q = float(cj.conic_value(jnp.asarray(coef), jnp.asarray(ab)))
    grad_ab = np.asarray(jax.grad(cj.conic_value, argnums=1)(jnp.asarray(coef), jnp.asarray(ab)))
    e_world = np.stack([V[1] - V[0], V[2] - V[0]])  # (2, 3): d(world point) / d(a, b)
    return abs(Q) / float(np.linalg.norm(np.linalg.pinv(e_world) @ grad_ab))


def run() -> tuple[dict, dict]:
    with cj.precision("float64"):
        scene = wavy_pool(**SCENE, dtype="float64")
        mesh = scene.surface
        P, L = np.array(P_RECEIVER), np.array(L_LIGHT)
        Vf, Nf = oracle.NumpyMesh.from_mesh(mesh).triangles(np.arange(mesh.faces.shape[0]))
        t0 = time.perf_counter()
        arcs, coef = trace_curve(jnp.asarray(Vf), jnp.asarray(Nf), jnp.asarray(P), jnp.asarray(L))
        trace_s = time.perf_counter() - t0
        log(f"traced {len(arcs)} arcs in {trace_s:.1f} s")

        # every sample: relative triple product (oracle, independent of the conic code),
        # |Q|, inside its face, spacing along its arc
        faces = np.concatenate([np.full(len(a["ab"]), a["face"]) for a in arcs])
        ab_all = np.concatenate([a["ab"] for a in arcs])
        rel = oracle.triple_product(Vf[faces], Nf[faces], P, L, ab_all, relative=True)
        conic = np.abs(np.asarray(jax.jit(cj.conic_value)(coef[faces], ab_all)))
        outside = int(np.sum(~oracle.inside_triangle(ab_all, INSIDE_TOL)))
        spacing = max(float(np.max(np.linalg.norm(np.diff(a["xyz"], axis=0), axis=-1))) for a in arcs)
        comps, join_gap = components(arcs)
        # topology: a component is a closed loop or ends on the pool's outer boundary
        lo, hi = Vf[..., :2].min((0, 1)), Vf[..., :2].max((0, 1))
        open_inside = 0
        for c in comps:
            q, _, _ = polyline(arcs, c)
            if np.linalg.norm(q[0] - q[-1]) > MATCH_TOL:
                for e in (q[0, :2], q[-1, :2]):
                    open_inside += not np.any(np.isclose(e, lo) | np.isclose(e, hi))

        # start point and the curve walk
        start = cj.start_points(mesh, P[None], L[None])
        sol = cj.solve(mesh, P[None], L[None], eta=ETA)
        f0, fM = int(start.face[0]), int(sol.triangle[0])
        ab0, abM = np.asarray(start.barycentric)[0], np.asarray(sol.barycentric)[0]
        M0 = oracle.barycentric_point(Vf[f0], ab0)
        M = np.asarray(sol.point)[0]
        # the component through M0 (the one the walk follows), oriented toward M
        main = int(np.argmin([distance_to_polyline(M0, polyline(arcs, c)[0]) for c in comps]))
        xyz, face_c, ab_c = polyline(arcs, comps[main])
        i0 = int(np.argmin(np.linalg.norm(xyz - M0, axis=-1)))
        iM = int(np.argmin(np.linalg.norm(xyz - M, axis=-1)))
        if iM < i0:
            xyz, face_c, ab_c = xyz[::-1], face_c[::-1], ab_c[::-1]
            i0, iM = len(xyz) - 1 - i0, len(xyz) - 1 - iM
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(xyz, axis=0), axis=-1))])
        s -= s[i0]
        dist_M0 = distance_to_polyline(M0, xyz)
        dist_M, s_M = distance_to_polyline(M, xyz, s)
        # f along every component (one call): roots of f anywhere on the traced curve form
        # an independent all-solutions reference for the walk's M
        polys = [(xyz, face_c, ab_c)] + [polyline(arcs, c) for k, c in enumerate(comps) if k != main]
        cat = [np.concatenate(x) for x in zip(*polys, strict=True)]
        f_all, st_all, g_all = (np.asarray(x) for x in _bracket_objective(
            jnp.asarray(Vf[cat[1]]), jnp.asarray(Nf[cat[1]]), jnp.asarray(P), jnp.asarray(L),
            jnp.asarray(cat[2]), ETA))
        split = np.cumsum([len(x[0]) for x in polys])[:-1]
        per_comp = [np.split(x, split) for x in (f_all, g_all, st_all)]
        f_curve, st_curve = per_comp[0][0], per_comp[2][0]
        roots_main = curve_roots(per_comp[0][0], per_comp[1][0], per_comp[2][0], s)
        roots_other = sum(
            len(curve_roots(f, g, st, np.zeros(len(f))))
            for f, g, st in zip(*(x[1:] for x in per_comp), strict=True)
        )
        cross = np.nonzero(np.diff(face_c))[0]
        s_edges = (s[cross] + s[cross + 1]) / 2  # where the curve crosses a triangle edge
        status_counts = {ObjectiveStatus(k).name: int(np.sum(st_curve == k)) for k in np.unique(st_curve)}

        out = dict(
            scene=scene.name,
            scene_kwargs=SCENE,
            triangles=int(mesh.faces.shape[0]),
            P=P,
            L=L,
            eta=ETA,
            dtype="float64",
            tracer="caustics_jax.curve.arcs.trace_arcs",
            samples_per_arc=SAMPLES,
            M0=M0,
            M0_face=f0,
            M=M,
            M_face=fM,
            M_barycentric=abM,
            solve_status=cj.Status(int(sol.status[0])).name,
            solve_residual_f=float(sol.residual[0]),
            solve_crossed=int(sol.crossed[0]),
            solve_iterations=int(sol.iterations[0]),
            curve_edges_between_M0_and_M=int(np.sum((s_edges > 0) & (s_edges < s_M))),
            f_roots_on_M0_component_brackets_m=roots_main,
            f_roots_on_other_components=int(roots_other),
            faces_on_curve=int(len({a["face"] for a in arcs})),
            arcs=len(arcs),
            components=len(comps),
            samples=int(len(ab_all)),
            trace_s=trace_s,
            max_rel_triple_product=float(rel.max()),
            max_abs_conic_value=float(conic.max()),
            samples_outside_their_face=outside,
            max_sample_spacing_m=spacing,
            max_join_gap_m=join_gap,
            open_curve_ends_not_on_boundary=int(open_inside),
            M0_rel_triple_product=float(oracle.triple_product(Vf[f0], Nf[f0], P, L, ab0, relative=True)),
            M0_distance_to_sampled_curve_m=dist_M0,
            M_rel_triple_product=float(oracle.triple_product(Vf[fM], Nf[fM], P, L, abM, relative=True)),
            M_distance_to_exact_curve_m=distance_to_conic(coef[fM], abM, Vf[fM]),
            M_distance_to_sampled_curve_m=dist_M,
            M_arc_length_from_M0_m=s_M,
            M_distance_from_M0_m=float(np.linalg.norm(M - M0)),
            objective_status_on_M0_component=status_counts,
            tir_fraction_of_main_component=float(np.mean(st_curve == ObjectiveStatus.TOTAL_INTERNAL_REFLECTION)),
        )
        plot_data = dict(
            mesh=mesh,
            arcs=arcs,
            comps=comps,
            main=main,
            xyz=xyz,
            s=s,
            f=f_curve,
            status=st_curve,
            s_edges=s_edges,
            P=P,
            L=L,
            M0=M0,
            M=M,
            s_M=s_M,
        )
    return out, plot_data


# %% [markdown]
# ## Figure


# %%
def _legend_once(ax, label):
    return label if label not in ax.get_legend_handles_labels()[1] else None


def plot(d, out, path=FIG):
    mesh = d["mesh"]
    Vx = np.asarray(mesh.vertices)
    F = np.asarray(mesh.faces)
    P, L, M0, M = d["P"], d["L"], d["M0"], d["M"]
    xyz, s, walked = d["xyz"], d["s"], (d["s"] >= 0) & (d["s"] <= d["s_M"])
    fig = plt.figure(figsize=(15, 8.8))
    gs = fig.add_gridspec(2, 2, width_ratios=[1.12, 1], height_ratios=[1, 1.15])
    ax, ax_side, ax_f = (
        fig.add_subplot(gs[:, 0]),
        fig.add_subplot(gs[0, 1]),
        fig.add_subplot(gs[1, 1]),
    )

    # ---- top view: height shading, wireframe, curve, points
    pale = matplotlib.colors.LinearSegmentedColormap.from_list(
        "pale_blues", plt.get_cmap("Blues_r")(np.linspace(0.45, 0.97, 256))
    )
    tpc = ax.tripcolor(Vx[:, 0], Vx[:, 1], F, Vx[:, 2], shading="gouraud", cmap=pale, zorder=0)
    edges = np.unique(
        np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), 1), axis=0
    )
    ax.add_collection(LineCollection(Vx[edges][:, :, :2], colors="0.6", linewidths=0.45, zorder=1))
    cb = fig.colorbar(tpc, ax=ax, shrink=0.6, pad=0.015, aspect=30)
    cb.set_label("water surface height z (m)")
    ax.plot(
        [P[0], L[0]],
        [P[1], L[1]],
        ":",
        color="0.2",
        lw=1.3,
        zorder=2,
        label="projection of segment PL (the curve of a flat surface)",
    )
    for k, chain in enumerate(d["comps"]):
        if k != d["main"]:
            c, _, _ = polyline(d["arcs"], chain)
            ax.plot(
                c[:, 0],
                c[:, 1],
                "--",
                color="C3",
                lw=1.4,
                zorder=3,
                label=_legend_once(ax, "coplanarity curve, other components"),
            )
    ax.plot(
        xyz[walked, 0],
        xyz[walked, 1],
        "-",
        color="gold",
        lw=8,
        alpha=0.75,
        zorder=3,
        solid_capstyle="round",
        label=r"walked by solve, $M_0 \to M$",
    )
    ax.plot(
        xyz[:, 0],
        xyz[:, 1],
        "-",
        color="C3",
        lw=2.0,
        zorder=4,
        label=r"coplanarity curve $\tilde n\cdot(PL\times PM)=0$ through $M_0$",
    )
    ax.plot(
        *P[:2], "v", ms=11, color="C0", mec="k", zorder=6, label=f"P, receiver (z = {P[2]:g} m)"
    )
    ax.plot(
        *L[:2],
        "*",
        ms=17,
        color="gold",
        mec="k",
        zorder=6,
        label=f"L, point light (z = {L[2]:g} m)",
    )
    ax.plot(
        *M0[:2],
        "o",
        ms=10,
        mfc="white",
        mec="k",
        mew=2,
        zorder=7,
        label=r"$M_0$ = segment PL $\cap$ surface (start point)",
    )
    ax.plot(
        *M[:2], "o", ms=9, color="C2", mec="k", zorder=8, label="M, refraction point from solve"
    )
    ax.set_aspect("equal")
    lo, hi = Vx[:, :2].min(0), Vx[:, :2].max(0)
    ax.set_xlim(lo[0] - 0.01, hi[0] + 0.01)
    ax.set_ylim(lo[1] - 0.01, hi[1] + 0.01)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(
        f"Top view: coplanarity curve on a wavy water surface (seed 001 Fig. 3)\n"
        f"{out['triangles']} triangles, |z| <= {SCENE['amplitude']:g} m, float64, eta = {ETA}\n"
        f"curve traced by caustics_jax.curve.arcs.trace_arcs, across {out['faces_on_curve']} faces",
        fontsize=10.5,
    )
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.07), ncol=2, fontsize=8, frameon=False)

    # ---- side view: everything projected on the vertical plane through P and L
    u_dir = (L - P)[:2] / np.linalg.norm((L - P)[:2])

    def u(q):
        return (np.asarray(q)[..., :2] - P[:2]) @ u_dir

    tri = matplotlib.tri.Triangulation(Vx[:, 0], Vx[:, 1], F)
    uu = np.linspace(u(Vx).min(), u(Vx).max(), 1500)
    line_xy = P[:2] + uu[:, None] * u_dir
    z_sec = matplotlib.tri.LinearTriInterpolator(tri, Vx[:, 2])(line_xy[:, 0], line_xy[:, 1])
    ax_side.fill_between(uu, -0.75, z_sec, color="C0", alpha=0.12, lw=0)
    ax_side.plot(uu, z_sec, "-", color="C0", lw=1.2, label="surface section under segment PL")
    ax_side.plot(u(xyz), xyz[:, 2], "-", color="C3", lw=1.4, label="coplanarity curve (height)")
    ax_side.plot(
        [u(P), u(L)], [P[2], L[2]], ":", color="0.2", lw=1.3, label=r"segment PL (through $M_0$)"
    )
    ax_side.plot(
        [u(P), u(M), u(L)],
        [P[2], M[2], L[2]],
        "-",
        color="C2",
        lw=1.5,
        label="refracted path P -> M -> L",
    )
    ax_side.plot(u(P), P[2], "v", ms=10, color="C0", mec="k")
    ax_side.plot(u(L), L[2], "*", ms=15, color="gold", mec="k")
    ax_side.plot(u(M0), M0[2], "o", ms=9, mfc="white", mec="k", mew=2, zorder=5)
    ax_side.plot(u(M), M[2], "o", ms=8, color="C2", mec="k", zorder=5)
    ax_side.set_aspect("equal")
    ax_side.set_ylim(P[2] - 0.1, L[2] + 0.1)
    ax_side.set_xlim(uu[0], uu[-1])
    ax_side.set_xlabel(r"horizontal distance from P along $P_p \to L_p$ (m)")
    ax_side.set_ylabel("z (m)")
    ax_side.set_title("Side view, projected on the vertical plane through P and L", fontsize=10.5)
    ax_side.legend(loc="upper left", fontsize=7.5)
    ax_side.grid(True, alpha=0.3)

    # ---- f along the component through M0
    f, status = d["f"], d["status"]
    tir = status == ObjectiveStatus.TOTAL_INTERNAL_REFLECTION
    backward = status == ObjectiveStatus.BACKWARD
    for se in d["s_edges"]:
        ax_f.axvline(se, color="0.88", lw=0.7, zorder=0)
    ax_f.axhline(0, color="0.3", lw=0.8)
    ax_f.axvspan(
        min(0, d["s_M"]), max(0, d["s_M"]), color="gold", alpha=0.3, lw=0, label="walked by solve"
    )
    ax_f.plot(
        s,
        np.where(status == ObjectiveStatus.OK, f, np.nan),
        "-",
        color="C3",
        lw=1.8,
        label=r"signed sine $f$ (seed 001 eq. 21, 'plane' sign)",
    )
    if tir.any():
        ax_f.plot(
            s[tir],
            np.zeros(tir.sum()),
            "-",
            color="k",
            lw=3,
            solid_capstyle="butt",
            label="total internal reflection seen from P (no path)",
        )
    if backward.any():
        ax_f.plot(
            s[backward],
            np.zeros(backward.sum()),
            "-",
            color="0.55",
            lw=3,
            solid_capstyle="butt",
            label="refracted ray points away from L (no path)",
        )
    ax_f.plot(
        0, np.interp(0, s, f), "o", ms=9, mfc="white", mec="k", mew=2, zorder=5, label=r"$M_0$"
    )
    ax_f.plot(
        d["s_M"],
        0,
        "o",
        ms=8,
        color="C2",
        mec="k",
        zorder=5,
        label=f"M ({out['solve_status']}, |f| = {abs(out['solve_residual_f']):.0e}, "
        f"{out['solve_crossed']} edges crossed)",
    )
    ax_f.set_xlim(s.min(), s.max())
    ax_f.set_xlabel(r"arc length along the curve from $M_0$ (m), positive toward M")
    ax_f.set_ylabel("signed sine f (dimensionless)")
    ax_f.set_title(
        r"Objective along the curve through $M_0$ (grey lines: triangle edges crossed)",
        fontsize=10.5,
    )
    ax_f.grid(True, axis="y", alpha=0.3)
    ax_f.legend(loc="best", fontsize=7.5, framealpha=0.92)
    n_roots = len(out["f_roots_on_M0_component_brackets_m"]) + out["f_roots_on_other_components"]
    roots = "M is the only root of f" if n_roots == 1 else f"f has {n_roots} roots"
    fig.suptitle(
        f"Coplanarity check (float64): max |n~.(PL x PM)| / (|n~| |PL| |PM|) = "
        f"{out['max_rel_triple_product']:.1e} over {out['samples']:,} curve samples, "
        f"{out['M_rel_triple_product']:.1e} at M (M is "
        f"{out['M_distance_to_sampled_curve_m']:.0e} m from the sampled curve); "
        f"{roots} on the whole traced curve",
        fontsize=10.5,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# %%
if __name__ == "__main__":
    t = time.perf_counter()
    out, data = run()
    plot(data, out)
    out["total_s"] = time.perf_counter() - t
    write_json(FIG.with_suffix(".json"), out)
    rows = [
        ("scene", out["scene"]),
        (
            "faces on the curve / arcs / components",
            f"{out['faces_on_curve']} / {out['arcs']} / {out['components']}",
        ),
        ("curve samples (float64, library tracer)", f"{out['samples']:,}"),
        ("max rel. triple product on samples", f"{out['max_rel_triple_product']:.2e}"),
        ("max |conic value| on samples", f"{out['max_abs_conic_value']:.2e}"),
        ("max gap where arcs join across edges (m)", f"{out['max_join_gap_m']:.2e}"),
        ("curve ends not on the mesh boundary", f"{out['open_curve_ends_not_on_boundary']}"),
        ("rel. triple product at M0", f"{out['M0_rel_triple_product']:.2e}"),
        (
            "solve status / f at M / edges crossed",
            f"{out['solve_status']} / {out['solve_residual_f']:.1e} / {out['solve_crossed']}",
        ),
        ("edges the traced curve crosses from M0 to M", f"{out['curve_edges_between_M0_and_M']}"),
        ("rel. triple product at M", f"{out['M_rel_triple_product']:.2e}"),
        (
            "roots of f on the curve: M0 component / others",
            f"{len(out['f_roots_on_M0_component_brackets_m'])} / "
            f"{out['f_roots_on_other_components']}",
        ),
        (
            "  bracket of the root on the M0 component (s, m)",
            ", ".join(f"[{a:.5f}, {b:.5f}]" for a, b in out["f_roots_on_M0_component_brackets_m"]),
        ),
        ("  arc length of M from M0 (s, m)", f"{out['M_arc_length_from_M0_m']:.5f}"),
        ("M distance to exact curve (m, 1st order)", f"{out['M_distance_to_exact_curve_m']:.2e}"),
        ("M distance to sampled polyline (m)", f"{out['M_distance_to_sampled_curve_m']:.2e}"),
        (
            "|M - M0| / arc length M0 -> M (m)",
            f"{out['M_distance_from_M0_m']:.3f} / {out['M_arc_length_from_M0_m']:.3f}",
        ),
        ("samples outside their face / max spacing (m)",
         f"{out['samples_outside_their_face']} / {out['max_sample_spacing_m']:.1e}"),
        ("M0 distance to sampled polyline (m)", f"{out['M0_distance_to_sampled_curve_m']:.2e}"),
        ("time (trace / total, s)", f"{out['trace_s']:.1f} / {out['total_s']:.1f}"),
    ]
    for k, v in rows:
        print(f"{k:53s} {v}")
    print(f"wrote {FIG} and {FIG.with_suffix('.json')}")
