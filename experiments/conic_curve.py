# %% [markdown]
# # The coplanarity curve across a wavy mesh (seed 001 Fig. 3)
#
# Question: what does the set of points `M` with `n~(a, b) . (PL x PM) = 0` (seed 001
# eq. 9-12, MATH.md §2) look like on a small wavy water surface, and does the curve walk
# (`caustics_jax.solve`) really travel along it from the start point `M0 = PL ∩ surface`
# to the refraction point `M`?
#
# The curve is traced exactly, triangle by triangle, in float64: each face's conic is cut
# by its edges (`edge_intersections`), and every arc inside the face is sampled through
# the pencil of lines through one edge root (`conic.conic_second_intersection`: every line
# through a point of a conic meets it in exactly one other point, so the line's angle
# parametrises the whole conic). Samples are refined until consecutive points are closer
# than `MAX_SEGMENT`. Every sample is an exact root of its face's conic up to rounding.
# Arcs are chained across shared edges into connected components; along the component
# through `M0` the signed sine `f` (seed 001 eq. 21, "plane" orientation) is evaluated.
#
# Run: `python -m experiments.conic_curve` (writes `figures/conic_curve.png` and `.json`,
# prints a table). Also `make figures`.

# %%
from __future__ import annotations

import functools
import json
import pathlib
import time

import jax
import jax.numpy as jnp
import matplotlib
import matplotlib.tri

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402

import caustics_jax as cj  # noqa: E402
from caustics_jax.conic import conic_second_intersection, edge_intersection_points  # noqa: E402
from caustics_jax.scenes import wavy_pool  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]
FIG = ROOT / "figures" / "conic_curve.png"

# A 14 x 14 cell heightfield (392 triangles) over a 2.1 m square, |z| <= 10 cm, wavelengths
# 0.5-1.2 m (3-8 cells): a curve that visibly bends, still resolved by the mesh.
SCENE = dict(n_triangles=392, seed=3, amplitude=0.1, wavelength=(0.5, 1.2), half_size=1.0)
P_RECEIVER = (-0.6, -0.5, -0.6)  # under the water (m)
L_LIGHT = (0.8, 0.6, 1.0)  # above it (m)
ETA = 1.333
N_PENCIL = 256  # initial pencil angles per face
MAX_SEGMENT = 2e-3  # refine arcs until consecutive samples are closer than this (m)
INSIDE_TOL = 1e-12  # barycentric slack of the inside-the-face test
MATCH_TOL = 1e-9  # arcs of neighbouring faces join when their ends are this close (m)


# %% [markdown]
# ## Tracing the conic inside each face


# %%
def _inside(ab, tol=INSIDE_TOL):
    return (ab[..., 0] >= -tol) & (ab[..., 1] >= -tol) & (ab[..., 0] + ab[..., 1] <= 1 + tol)


def _interior_ellipse_anchor(coef):
    """A point of the conic when it is an ellipse wholly inside the face (no edge root),
    as in `solvers.exhaustive._touches`; None otherwise."""
    A, B, C, D, E, F = coef
    det = 4 * A * B - C * C
    if det <= 0:
        return None
    centre = np.array([(C * E - 2 * B * D) / det, (C * D - 2 * A * E) / det])
    value = (
        A * centre[0] ** 2
        + B * centre[1] ** 2
        + C * centre[0] * centre[1]
        + D * centre[0]
        + E * centre[1]
        + F
    )
    if not (_inside(centre, 0) and value * F < 0):
        return None
    # the line b = b_c through the centre: A a^2 + (C b_c + D) a + (B b_c^2 + E b_c + F) = 0
    b = centre[1]
    roots, ok = cj.solve_quadratic(
        jnp.asarray(A), jnp.asarray(C * b + D), jnp.asarray(B * b * b + E * b + F)
    )
    return np.array([float(roots[1]), b]) if bool(ok[1]) else None


def pencil_point(coef, x0, phi):
    """Second point where the line through `x0` (on the conic) at angle `phi` meets it.

    numpy transcription of `conic.conic_second_intersection` (called once per face
    instead of once per refinement step: eager JAX dispatch would dominate the run time;
    `run` checks the two agree). `Q(x0 + s d) = Q0 + s (grad . d) + s^2 (d^T S2 d)`; the
    root of larger magnitude is the new point; invalid when the line is parallel to an
    asymptote (point at infinity).
    """
    A, B, C, D, E, F = coef
    da, db = np.cos(phi), np.sin(phi)
    q2 = A * da * da + B * db * db + C * da * db
    q1 = (2 * A * x0[0] + C * x0[1] + D) * da + (2 * B * x0[1] + C * x0[0] + E) * db
    q0 = A * x0[0] ** 2 + B * x0[1] ** 2 + C * x0[0] * x0[1] + D * x0[0] + E * x0[1] + F
    disc = q1 * q1 - 4 * q2 * q0
    ok = (q2 != 0) & (disc > 0)
    q = -(q1 + np.where(q1 >= 0, 1, -1) * np.sqrt(np.where(ok, disc, 0))) / 2
    with np.errstate(divide="ignore", invalid="ignore"):
        r1, r2 = q / np.where(ok, q2, 1), q0 / np.where(q != 0, q, 1)
    s = np.where(np.abs(r1) > np.abs(r2), r1, r2)
    ok &= np.isfinite(s)
    s = np.where(ok, s, 0)
    return x0 + s[:, None] * np.stack([da, db], -1), ok


def trace_face(coef, V, roots):
    """Arcs of the conic `coef` inside the face `V` (3, 3): a list of `(k, 2)` barycentric
    polylines whose ends are edge roots (or closed loops for an interior ellipse).

    `roots`: `(m, 2)` barycentric edge roots of the face. The pencil through the anchor
    `x0` (the first root) is swept over `phi in (phi_t, phi_t + pi)` from the tangent
    direction at `x0`, so the parameter runs once around the conic from `x0` back to it
    (a hyperbola passes through infinity in between, outside the face). The other roots
    are inserted at their own angles, so runs of inside samples end exactly on edges.
    """
    closed = len(roots) == 0
    x0 = _interior_ellipse_anchor(coef) if closed else roots[0]
    if x0 is None:
        return []
    A, B, C, D, E = coef[:5]
    tangent = np.array([-(C / 2 * x0[0] + B * x0[1] + E / 2), A * x0[0] + C / 2 * x0[1] + D / 2])
    if not np.any(tangent):
        return []  # singular point of a degenerate conic: not met on generic meshes
    phi_t = np.arctan2(tangent[1], tangent[0])

    def point(phi):
        return pencil_point(coef, x0, phi)

    phi = phi_t + np.pi * (np.arange(1, N_PENCIL) / N_PENCIL)
    ab, ok = point(phi)
    # the other edge roots at their pencil angles, reduced to (phi_t, phi_t + pi)
    v = roots[1:] - x0
    far = np.linalg.norm(v, axis=-1) > 1e-12
    phi_r = phi_t + np.mod(np.arctan2(v[far, 1], v[far, 0]) - phi_t, np.pi)
    phi = np.concatenate([[phi_t], phi, phi_r, [phi_t + np.pi]])
    ab = np.concatenate([x0[None], ab, roots[1:][far], x0[None]])
    keep = np.concatenate([[True], _inside(ab[1:N_PENCIL]) & ok, np.ones(far.sum() + 1, bool)])
    order = np.argsort(phi, kind="stable")
    phi, ab, keep = phi[order], ab[order], keep[order]

    # Refine where consecutive inside samples are too far apart in the world. A midpoint
    # outside the face splits the run there (an excursion through a corner, or the two
    # branches of a hyperbola): run ends then stay exact edge roots.
    e = np.stack([V[1] - V[0], V[2] - V[0]])  # (2, 3): world point = V0 + ab @ e
    for _ in range(40):
        gap = np.linalg.norm(np.diff(ab, axis=0) @ e, axis=-1)
        wide = np.nonzero((gap > MAX_SEGMENT) & keep[:-1] & keep[1:])[0]
        if len(wide) == 0:
            break
        mid = (phi[wide] + phi[wide + 1]) / 2
        new, ok = point(mid)
        phi = np.insert(phi, wide + 1, mid)
        ab = np.insert(ab, wide + 1, new, axis=0)
        keep = np.insert(keep, wide + 1, _inside(new) & ok)
    arcs = []
    for run in np.split(np.arange(len(phi)), np.nonzero(np.diff(keep.astype(int)))[0] + 1):
        if keep[run[0]] and len(run) >= 2:  # else outside, or an isolated root (tangency,
            arcs.append(ab[run])  # the anchor's outward side)
    if closed and arcs:
        arcs = [np.concatenate(arcs)]  # one loop, starting and ending at the anchor
    return arcs


@jax.jit
def _conics(V, N, P, L):
    coef = cj.conic_coefficients(V, N, P, L)
    t, valid = cj.edge_intersections(coef)
    return coef, edge_intersection_points(t), valid


def trace_curve(V, N, P, L):
    """Every arc of the coplanarity curve on the faces `V, N` `(F, 3, 3)`: a list of dicts
    (face, ab, xyz), and the conic coefficients `(F, 6)`."""
    coef, ab_roots, valid = (np.asarray(x) for x in _conics(V, N, P, L))
    arcs = []
    for f in range(len(V)):
        roots = ab_roots[f][valid[f]]
        if len(roots) == 0 and _interior_ellipse_anchor(coef[f]) is None:
            continue
        for ab in trace_face(coef[f], V[f], roots):
            xyz = V[f, 0] + ab[:, :1] * (V[f, 1] - V[f, 0]) + ab[:, 1:] * (V[f, 2] - V[f, 0])
            arcs.append(dict(face=f, ab=ab, xyz=xyz))
    return arcs, coef


def triple_product_residual(V, N, P, L, ab):
    """`|n~ . (PL x PM)| / (|n~| |PL| |PM|)`: the relative coplanarity residual."""
    a, b = ab[:, :1], ab[:, 1:]
    M = V[:, 0] + a * (V[:, 1] - V[:, 0]) + b * (V[:, 2] - V[:, 0])
    n = N[:, 0] + a * (N[:, 1] - N[:, 0]) + b * (N[:, 2] - N[:, 0])
    c = np.sum(n * np.cross(L - P, M - P), -1)
    return np.abs(c) / (
        np.linalg.norm(n, axis=-1) * np.linalg.norm(L - P) * np.linalg.norm(M - P, axis=-1)
    )


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
@jax.jit
def _library_pencil(coef, x0, phi):
    d = jnp.stack([jnp.cos(phi), jnp.sin(phi)], -1)
    return conic_second_intersection(coef[:, None], x0[:, None], d[None])


@functools.partial(jax.jit, static_argnames="eta")
def _signed_sine(V, N, P, L, ab, eta):
    """`f` with the "plane" and the "line" sign, and the status (`objectives.py`)."""
    f, status = cj.signed_sine_and_status(V, N, P, L, ab, eta, orientation="plane")
    g, _ = cj.signed_sine_and_status(V, N, P, L, ab, eta, orientation="line")
    return f, g, status


def curve_roots(f, g, status, s):
    """Brackets `(s_lo, s_hi)` of the roots of `f` along one component: both signs flip
    between consecutive samples (a root, not an orientation flip; as `walk._root_between`)
    and neither sample is under total internal reflection."""
    ok = (status[:-1] == 0) & (status[1:] == 0)
    flip = (np.sign(f[:-1]) * np.sign(f[1:]) < 0) & (np.sign(g[:-1]) * np.sign(g[1:]) < 0) & ok
    i = np.nonzero(flip)[0]
    return np.stack([s[i], s[i + 1]], -1)


def run() -> tuple[dict, dict]:
    with cj.precision("float64"):
        scene = wavy_pool(**SCENE, dtype="float64")
        mesh = scene.surface
        P, L = np.array(P_RECEIVER), np.array(L_LIGHT)
        Vf = np.asarray(mesh.vertices)[np.asarray(mesh.faces)]  # (F, 3, 3)
        Nf = np.asarray(mesh.normals)[np.asarray(mesh.faces)]
        t0 = time.perf_counter()
        arcs, coef = trace_curve(Vf, Nf, P, L)
        trace_s = time.perf_counter() - t0

        # every sample: relative triple product (independent of the conic code) and |Q|
        faces = np.concatenate([np.full(len(a["ab"]), a["face"]) for a in arcs])
        ab_all = np.concatenate([a["ab"] for a in arcs])
        rel = triple_product_residual(Vf[faces], Nf[faces], P, L, ab_all)
        conic = np.abs(np.asarray(jax.jit(cj.conic_value)(coef[faces], ab_all)))
        # the numpy pencil against the library's conic_second_intersection, on every arc
        x0 = np.stack([a["ab"][0] for a in arcs])
        coef_arcs = coef[[a["face"] for a in arcs]]
        phis = np.linspace(0.05, np.pi - 0.05, 64)
        lib, ok_lib = (np.asarray(x) for x in _library_pencil(coef_arcs, x0, phis))
        mine = [pencil_point(c, x, phis) for c, x in zip(coef_arcs, x0, strict=True)]
        ok = np.stack([m[1] for m in mine])
        mine = np.stack([m[0] for m in mine])
        both = ok & ok_lib & _inside(mine, 1.0)  # compare near the face
        pencil_diff = float(np.max(np.abs(mine - lib)[both], initial=0.0))
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
        M0 = Vf[f0, 0] + ab0 @ (Vf[f0, 1:] - Vf[f0, 0])
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
        dist_M, s_M = distance_to_polyline(M, xyz, s)
        # f along every component (one call): roots of f anywhere on the traced curve form
        # an independent all-solutions reference for the walk's M
        polys = [(xyz, face_c, ab_c)] + [
            polyline(arcs, c) for k, c in enumerate(comps) if k != main
        ]
        cat = [np.concatenate(x) for x in zip(*polys, strict=True)]
        f_all, g_all, st_all = (
            np.asarray(x) for x in _signed_sine(Vf[cat[1]], Nf[cat[1]], P, L, cat[2], ETA)
        )
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

        # how far M is from the curve: relative triple product, and the first-order world
        # distance |Q| / |grad_world Q| in its face
        A, B, C, D, E, _ = coef[fM]
        grad_ab = np.array([2 * A * abM[0] + C * abM[1] + D, 2 * B * abM[1] + C * abM[0] + E])
        e_world = Vf[fM, 1:] - Vf[fM, 0]  # (2, 3); world point = V0 + ab @ e_world
        grad_world = np.linalg.pinv(e_world) @ grad_ab  # tangent-plane gradient
        Q_M = float(cj.conic_value(jnp.asarray(coef[fM]), jnp.asarray(abM)))

        out = dict(
            scene=scene.name,
            scene_kwargs={k: list(v) if isinstance(v, tuple) else v for k, v in SCENE.items()},
            triangles=int(mesh.faces.shape[0]),
            P=P.tolist(),
            L=L.tolist(),
            eta=ETA,
            dtype="float64",
            M0=M0.tolist(),
            M0_face=f0,
            M=M.tolist(),
            M_face=fM,
            M_barycentric=abM.tolist(),
            solve_status=cj.Status(int(sol.status[0])).name,
            solve_residual_f=float(sol.residual[0]),
            solve_crossed=int(sol.crossed[0]),
            solve_iterations=int(sol.iterations[0]),
            curve_edges_between_M0_and_M=int(np.sum((s_edges > 0) & (s_edges < s_M))),
            f_roots_on_M0_component_brackets_m=roots_main.tolist(),
            f_roots_on_other_components=int(roots_other),
            faces_on_curve=int(len({a["face"] for a in arcs})),
            arcs=len(arcs),
            components=len(comps),
            samples=int(len(ab_all)),
            trace_s=trace_s,
            max_rel_triple_product=float(rel.max()),
            max_abs_conic_value=float(conic.max()),
            max_join_gap_m=join_gap,
            open_curve_ends_not_on_boundary=int(open_inside),
            pencil_numpy_vs_library_max_diff=pencil_diff,
            M0_rel_triple_product=float(
                triple_product_residual(Vf[[f0]], Nf[[f0]], P, L, ab0[None])[0]
            ),
            M_rel_triple_product=float(
                triple_product_residual(Vf[[fM]], Nf[[fM]], P, L, abM[None])[0]
            ),
            M_distance_to_exact_curve_m=abs(Q_M) / float(np.linalg.norm(grad_world)),
            M_distance_to_sampled_curve_m=dist_M,
            M_arc_length_from_M0_m=s_M,
            M_distance_from_M0_m=float(np.linalg.norm(M - M0)),
            tir_fraction_of_main_component=float(np.mean(st_curve != 0)),
        )
        plot_data = dict(
            mesh=mesh,
            arcs=arcs,
            comps=comps,
            main=main,
            xyz=xyz,
            s=s,
            f=f_curve,
            tir=st_curve != 0,
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
        f"{out['triangles']} triangles, |z| <= {SCENE['amplitude']:g} m, float64; "
        f"curve crosses {out['faces_on_curve']} faces; eta = {ETA}",
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
    f, tir = d["f"], d["tir"]
    for se in d["s_edges"]:
        ax_f.axvline(se, color="0.88", lw=0.7, zorder=0)
    ax_f.axhline(0, color="0.3", lw=0.8)
    ax_f.axvspan(
        min(0, d["s_M"]), max(0, d["s_M"]), color="gold", alpha=0.3, lw=0, label="walked by solve"
    )
    ax_f.plot(
        s,
        np.where(tir, np.nan, f),
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
    path.parent.mkdir(exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


# %%
if __name__ == "__main__":
    t = time.perf_counter()
    out, data = run()
    plot(data, out)
    out["total_s"] = time.perf_counter() - t
    FIG.with_suffix(".json").write_text(json.dumps(out, indent=1))
    rows = [
        ("scene", out["scene"]),
        (
            "faces on the curve / arcs / components",
            f"{out['faces_on_curve']} / {out['arcs']} / {out['components']}",
        ),
        ("curve samples (float64)", f"{out['samples']:,}"),
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
        (
            "numpy pencil vs conic_second_intersection",
            f"{out['pencil_numpy_vs_library_max_diff']:.1e}",
        ),
        ("time (trace / total, s)", f"{out['trace_s']:.1f} / {out['total_s']:.1f}"),
    ]
    for k, v in rows:
        print(f"{k:53s} {v}")
    print(f"wrote {FIG} and {FIG.with_suffix('.json')}")
