"""Brute-force photon tracing: the reference caustic irradiance on a receiver plane.

Photons leave a point light `L` through an *emission plane*: the horizontal rectangle
that covers the surface's xy extent at a height `z_e` just above its highest vertex
(a light-view parametrisation of the surface, like the caustic maps of seed 004 §3.1).
A photon through the plane point `X` has direction `d = (X - L)/r_e`, `r_e = |X - L|`;
with `X` uniform on the rectangle (area `A_e`) the solid-angle density is
`r_e^2 / (A_e cos_e)`, `cos_e = (L_z - z_e)/r_e`, so each of `n` photons carries flux

    Phi = I_e A_e cos_e / (n r_e^2)

A directional light (`Directional`, irradiance `E_perp` perpendicular to its rays) sends
parallel photons along its `direction` `d` through `X` uniform on the plane: the plane's
cross-section perpendicular to the rays is `A_e |d_z|`, so each carries
`Phi = E_perp A_e |d_z| / n`.

It hits the surface exactly (the segment/triangle kernel of `start_points`: grid DDA on
heightfields, BVH otherwise), refracts at the interpolated normal (GLSL `refract` from
air, index ratio `1/eta`) carrying the exact Fresnel transmittance `T`, and is
attenuated by `exp(-sigma_t t)` over its path `t` to the receiver plane `z = z_r`, where
its flux is binned. A cell's irradiance is its binned flux over its area; its standard
error `sqrt(sum Phi_i^2)/area` (each photon lands in a cell independently). Photons that
meet the surface from below its shading normal, or miss it, carry nothing.

Chunks of photons are traced jitted (one compile per chunk size) and binned on the host
in float64, so 10^7-10^8 photons run in minutes on a CPU. Exactly `n_photons` photons are
emitted: the last chunk's surplus lanes carry nothing, and a count below the chunk size
traces one chunk of the power of two above it (at least 256), not a whole default chunk.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..accel.prepared import PreparedSurface, kept_accel, prepare
from ..accel.start_points import first_crossing
from ..math.barycentric import barycentric_point, interpolated_normal
from ..math.geometry import beer_lambert, dot, fresnel_transmittance, refract, safe_normalize
from ..runtime.arguments import check_eta, check_fits, check_int, check_points, check_real
from ..runtime.lanes import power_of_two_bucket
from ..runtime.precision import check_mesh_dtype
from ..runtime.progress import progress as progress_bar
from ..surface.lights import Directional
from ..surface.mesh import SurfaceMesh

#: Largest `n_photons` of one `photon_irradiance` call: 2^32 photons are hours of tracing on
#: a CPU (the experiments use up to 2^26); a larger count is a typo, refused rather than
#: left running for days.
MAX_PHOTONS = 2**32


class ReceiverGrid(NamedTuple):
    """A horizontal receiver plane `z = z` (normal +z), binned into `nx x ny` cells.

    Cells cover `[x0, x1] x [y0, y1]`; cell `(j, i)` (row `j` along y, column `i` along
    x) has centre `(x0 + (i + 1/2) dx, y0 + (j + 1/2) dy, z)`.
    """

    z: float
    x0: float
    x1: float
    y0: float
    y1: float
    nx: int
    ny: int

    @property
    def dx(self) -> float:
        return (self.x1 - self.x0) / self.nx

    @property
    def dy(self) -> float:
        return (self.y1 - self.y0) / self.ny

    @property
    def cell_area(self) -> float:
        return self.dx * self.dy

    @property
    def normal(self) -> np.ndarray:
        return np.array([0.0, 0.0, 1.0])

    def centers(self) -> np.ndarray:
        """`(ny, nx, 3)` cell centres (float64)."""
        return self.subsamples(1)[:, :, 0]

    def subsamples(self, k: int) -> np.ndarray:
        """`(ny, nx, k*k, 3)`: a `k x k` midpoint grid in each cell (float64).

        Averaging a point quantity over them is the midpoint rule for its cell average,
        which is what a binned photon estimate converges to.
        """
        s = (np.arange(k) + 0.5) / k
        sx = self.x0 + (np.arange(self.nx)[:, None] + s[None]).reshape(-1) * self.dx
        sy = self.y0 + (np.arange(self.ny)[:, None] + s[None]).reshape(-1) * self.dy
        X, Y = np.meshgrid(sx, sy, indexing="xy")  # (ny k, nx k)
        pts = np.stack([X, Y, np.full_like(X, self.z)], -1)
        pts = pts.reshape(self.ny, k, self.nx, k, 3).transpose(0, 2, 1, 3, 4)
        return pts.reshape(self.ny, self.nx, k * k, 3)

    def cells(self, xy, valid=None, origin=(0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
        """The flat cell index `j nx + i` of each point `xy` (`(N, >=2)`, numpy, in a frame
        moved by `origin`: the grid's bounds minus `origin[:2]`) and whether it lands on the
        grid (and is `valid`); a point outside gets cell 0, so `np.bincount(cell, weight *
        inside, nx ny)` bins every point in one call. A cell is half-open, `[x0 + i dx,
        x0 + (i + 1) dx)`, and `x1`, `y1` are outside. The one binning of receiver points:
        photon maps, the culling and budget experiments and the notebooks use it."""
        xy = np.asarray(xy)
        ix = np.floor((xy[:, 0] - (self.x0 - origin[0])) / self.dx)
        iy = np.floor((xy[:, 1] - (self.y0 - origin[1])) / self.dy)
        inside = (ix >= 0) & (ix < self.nx) & (iy >= 0) & (iy < self.ny)
        if valid is not None:
            inside &= np.asarray(valid, bool)
        return np.where(inside, iy * self.nx + ix, 0).astype(np.int64), inside

    @classmethod
    def check(cls, receiver, name: str = "receiver") -> ReceiverGrid:
        """`receiver` (a `ReceiverGrid` or its 7 fields) validated: finite bounds with
        `x1 > x0`, `y1 > y0`, integer `nx, ny` in `[1, 2^15]` (an empty grid bins nothing
        and is refused); `ValueError` naming `name` otherwise."""
        try:
            grid = cls(*receiver)
        except TypeError:
            raise ValueError(f"{name} must be a ReceiverGrid(z, x0, x1, y0, y1, nx, ny), got {receiver!r}") from None
        for field in ("z", "x0", "x1", "y0", "y1"):
            check_real(f"{name}.{field}", getattr(grid, field))
        nx, ny = (check_int(f"{name}.{f}", getattr(grid, f), 1, 2**15) for f in ("nx", "ny"))
        grid = grid._replace(**{f: float(getattr(grid, f)) for f in ("z", "x0", "x1", "y0", "y1")}, nx=nx, ny=ny)
        if not (grid.x1 > grid.x0 and grid.y1 > grid.y0):
            raise ValueError(f"{name} needs x1 > x0 and y1 > y0, got {grid}")
        return grid

    def validate(self) -> None:
        """Raise `ValueError` unless the grid is usable (see `check`)."""
        ReceiverGrid.check(self)


class EmissionPlane(NamedTuple):
    """The rectangle photons are emitted through: `[x0, x1] x [y0, y1]` at height `z`."""

    z: float
    x0: float
    x1: float
    y0: float
    y1: float

    @property
    def area(self) -> float:
        return (self.x1 - self.x0) * (self.y1 - self.y0)

    @classmethod
    def covering(cls, mesh: SurfaceMesh, L) -> EmissionPlane:
        """The surface's xy bounding box just above its highest vertex; needs `L` above it
        (a `Directional`: travelling down)."""
        V = np.asarray(mesh.vertices, np.float64)
        lo, hi = V.min(0), V.max(0)
        z_e = hi[2] + 1e-3 * max(hi[2] - lo[2], 1e-3 * float(np.max(hi[:2] - lo[:2])))
        if isinstance(L, Directional):
            if not L.direction[2] < 0:
                raise ValueError(f"the directional light must travel down onto the surface (direction z < 0), "
                                 f"got direction {L.direction.tolist()}")
        else:
            L = np.asarray(L, np.float64).reshape(3)
            if not L[2] > z_e:
                raise ValueError(f"L, the light (z = {L[2]}), must be above the surface (max z = {hi[2]})")
        return cls(float(z_e), float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1]))


class PhotonMap(NamedTuple):
    """Binned photon irradiance on a `ReceiverGrid`.

    Attributes:
        irradiance: `(ny, nx)` W/m^2 (float64).
        stderr: `(ny, nx)` Monte-Carlo standard error of `irradiance`, estimated from the
            photons in the cell (`sqrt(sum Phi_i^2) / area`): 0 where no photon landed
            (`hits == 0`), which bounds nothing there, and unreliable where few did; read
            it with `hits`.
        hits: `(ny, nx)` photons binned per cell.
        n_photons: photons emitted (the `n_photons` asked for).
        receiver: the grid.
    """

    irradiance: np.ndarray
    stderr: np.ndarray
    hits: np.ndarray
    n_photons: int
    receiver: ReceiverGrid


def surface_hits(mesh: SurfaceMesh, L, X, *, bvh=None):
    """First hit `(face, ab, found)` of the rays from `L` through the points `X` (jitted core).

    The segment runs from `L` past `X` to below the surface's lowest vertex, and
    `start_points`' kernels return the crossing nearest its first end, the light.
    `L` `(3,)` or `(N, 3)`, `X` `(N, 3)`; concrete input (outside jit) must be finite with
    every `X` below `L` (a ray that does not go down never meets the surface from above):
    `ValueError` otherwise.
    """
    if not isinstance(mesh, SurfaceMesh):
        raise ValueError(f"mesh must be a SurfaceMesh, got {type(mesh).__name__}")
    check_mesh_dtype(mesh.dtype)
    if np.ndim(X) != 2 or np.shape(X)[-1] != 3 or np.shape(L)[-1:] != (3,) or np.ndim(L) > 2:
        raise ValueError(f"X must have shape (N, 3) and L (3,) or (N, 3), got {np.shape(X)} and {np.shape(L)}")
    if not isinstance(X, jax.core.Tracer) and not isinstance(L, jax.core.Tracer):
        X_np, L_np = check_points("X", X, mesh.dtype), check_points("L", L, mesh.dtype)
        if np.any(np.broadcast_to(X_np[:, 2] >= L_np[..., 2], X_np.shape[:1])):
            raise ValueError("every X must lie below L (the rays go down from the light)")
    X, L = jnp.asarray(X, mesh.dtype), jnp.asarray(L, mesh.dtype)
    z_lo = jnp.min(mesh.vertices[:, 2])
    z_hi = jnp.max(mesh.vertices[:, 2])
    d = X - L
    # Extend to a height (z_hi - z_lo) + 1 below the lowest vertex (d_z < 0 checked by callers).
    s_far = (L[..., 2] - z_lo + (z_hi - z_lo) + 1) / jnp.maximum(-d[..., 2], jnp.finfo(d.dtype).tiny)
    end = L + s_far[..., None] * d
    L_b = jnp.broadcast_to(L, end.shape)
    # The structure `prepare` keeps for this mesh: binning the faces on every call would cost
    # more than tracing a few rays (docs/mesh.md, "Measurements behind the code").
    return first_crossing(mesh, L_b, end, bvh=bvh, accel=None if bvh is not None else kept_accel(mesh))


def refract_into_medium(d, n_s, eta):
    """`(r, T, ok)`: GLSL `refract(d, n_s, 1/eta)` from the light's side, its Fresnel `T`.

    `ok` is False where the ray meets the shading normal from below (`d.n_s >= 0`).
    """
    cos_i = -dot(d, n_s)
    ok = cos_i > 0
    return refract(d, n_s, 1 / eta), fresnel_transmittance(cos_i, 1 / eta), ok


def emitted_flux(L, X, z_e, intensity, area_per_photon):
    """Flux of photons from a point light `L` through emission-plane points `X` (height
    `z_e`), each standing for `area_per_photon` of the plane: `Phi = I_e cos_e A / r_e^2`,
    `cos_e = (L_z - z_e)/r_e` (module docstring; `A = A_e / n` for uniform emission), in an
    order that stays finite for a far light in float32 (`I_e / r_e^2` first). Also `d`,
    the unit directions `(X - L)/r_e`."""
    d_raw = X - L
    r_e = jnp.linalg.norm(d_raw, axis=-1)
    return intensity / r_e**2 * ((L[..., 2] - z_e) / r_e) * area_per_photon, d_raw / r_e[..., None]


def propagate_photons(mesh, bvh, X, d, span, z_r, eta):
    """`(Y, T, t, valid, cos_i)` of photons through emission-plane points `X` along unit `d`
    (jitted core): each ray starts `span` back from `X` along `-d` (not at the light:
    float32 resolves a point 1.5e11 m away only to its ulp, 1.6e4 m), hits the surface
    (`surface_hits`), refracts at the interpolated normal with the exact Fresnel
    transmittance `T` and reaches the receiver plane `z = z_r` at `Y` (xy) after the path
    `t` in the medium; `cos_i` is the cosine of incidence on the shading normal. `valid` is
    False where it misses the surface, meets it from below its shading normal, or does not
    go down after refracting."""
    face, ab, found = surface_hits(mesh, X - span * d, X, bvh=bvh)
    V, N = mesh.triangle(face)
    M = barycentric_point(V, ab)
    n_s = safe_normalize(interpolated_normal(N, ab))
    r, T, ok = refract_into_medium(d, n_s, eta)
    down = r[:, 2] < 0
    t = (z_r - M[:, 2]) / jnp.where(down, r[:, 2], -1)
    Y = M + t[:, None] * r
    return Y[:, :2], T, t, found & ok & down, -dot(d, n_s)


@functools.partial(jax.jit, static_argnames=("chunk", "at_infinity"))
def _trace_chunk(mesh, bvh, key, L, plane, z_r, eta, sigma_t, intensity, n_total, count, chunk: int,
                 at_infinity: bool = False):
    """`chunk` photons, the first `count` of them emitted: their receiver-plane hits
    `(chunk, 2)`, flux `(chunk,)` and validity (False for the rest). `at_infinity`: `L` is
    a directional light's `direction` and `intensity` its `E_perp`."""
    dtype = mesh.dtype
    z_e, x0, x1, y0, y1 = plane
    u = jax.random.uniform(key, (chunk, 2), dtype)
    X = jnp.stack([x0 + u[:, 0] * (x1 - x0), y0 + u[:, 1] * (y1 - y0), jnp.full(chunk, z_e)], -1)
    A_e = (x1 - x0) * (y1 - y0)
    if at_infinity:
        # Parallel rays: the plane's cross-section perpendicular to them is A_e |d_z|, so
        # Phi = E_perp A_e |d_z| / n (module docstring).
        d = jnp.broadcast_to(L, X.shape)
        flux = jnp.full(chunk, intensity * A_e * -L[2] / n_total)
    else:
        flux, d = emitted_flux(L, X, z_e, intensity, A_e / n_total)
    Y, T, t, hit, _ = propagate_photons(mesh, bvh, X, d, (x1 - x0) + (y1 - y0), z_r, eta)
    valid = hit & (jnp.arange(chunk) < count)
    w = jnp.where(valid, flux * T * beer_lambert(sigma_t, t), 0)
    return Y, w.astype(dtype), valid


@jax.jit
def _trace_points(mesh, bvh, L, X, plane, z_r, eta, intensity, area):
    flux, d = emitted_flux(L, X, plane[0], intensity, area)
    Y, T, t, valid, cos_i = propagate_photons(mesh, bvh, X, d, (plane[2] - plane[1]) + (plane[4] - plane[3]), z_r,
                                              eta)
    return Y, flux, T, t, valid, cos_i


class PhotonHits(NamedTuple):
    """Photons traced one by one (`trace_photons`), numpy float64, in the caller's frame.

    Attributes:
        Y: `(N, 2)` xy of the receiver-plane hit.
        flux: `(N,)` emitted flux (W) of each photon.
        T: `(N,)` exact Fresnel transmittance at the surface.
        t: `(N,)` path length in the medium (m).
        valid: `(N,)` False where the photon misses the surface, meets it from below its
            shading normal or does not reach the receiver plane; such photons carry nothing.
        cos_i: `(N,)` cosine of incidence on the shading normal, the light's side
            (`T = fresnel_transmittance(cos_i, 1 / eta)`).
    """

    Y: np.ndarray
    flux: np.ndarray
    T: np.ndarray
    t: np.ndarray
    valid: np.ndarray
    cos_i: np.ndarray


def trace_photons(mesh: SurfaceMesh | PreparedSurface, L, X, *, intensity: float, area, eta: float = 1.333,
                  receiver_z: float) -> PhotonHits:
    """Photons from a point light `L` through the emission-plane points `X`, traced one by one.

    The building block of `photon_irradiance` for callers that emit their own photons
    (stratified per light-space texel, with an adaptive budget) or act on each photon
    before binning (seed 003's culling, `kernels.photon_cull`). `X` `(N, 3)` must lie on
    `EmissionPlane.covering(mesh, L)` (its `z`); each photon stands for `area` (scalar or
    `(N,)`, m^2) of the plane, so its flux is `I_e cos_e area / r_e^2` (module docstring):
    with `area = A_e / N` for uniform `X` the photons estimate the irradiance as
    `photon_irradiance` does. The energy a photon brings to the receiver is
    `flux T exp(-sigma_t t)`. Traced in the mesh's dtype (padded to a power of two, one
    compile per size), returned in float64.
    """
    prep = prepare(mesh)
    dtype = prep.dtype
    L_np = check_points("L", L, dtype)
    if L_np.shape != (3,):
        raise ValueError(f"L must be one point of shape (3,), got {L_np.shape}")
    X_np = check_points("X", X, dtype)
    if X_np.ndim != 2 or X_np.shape[1] != 3:
        raise ValueError(f"X must have shape (N, 3), got {X_np.shape}")
    plane = EmissionPlane.covering(prep.mesh, L_np)
    if not np.allclose(X_np[:, 2], plane.z, rtol=0, atol=1e-9 * max(1.0, abs(plane.z))):
        raise ValueError(f"X must lie on the emission plane z = {plane.z} (EmissionPlane.covering(mesh, L))")
    n = len(X_np)
    try:
        area_np = np.broadcast_to(np.asarray(area, np.float64), (n,))
    except (TypeError, ValueError):
        raise ValueError(f"area must be a number or one per photon ({n},), got {np.shape(area)}") from None
    if not np.all(np.isfinite(area_np)) or np.any(area_np < 0):
        raise ValueError("area must be finite and >= 0 (m^2 of the emission plane per photon)")
    intensity = check_fits("intensity", check_real("intensity", intensity, 0), dtype)
    eta = check_fits("eta", check_eta(eta), dtype, positive=True)
    receiver_z = check_real("receiver_z", receiver_z)
    if receiver_z >= float(np.min(np.asarray(prep.mesh.vertices)[:, 2])):
        raise ValueError(f"the receiver plane (receiver_z = {receiver_z}) must lie below the surface")
    origin = prep.origin
    local = prep.local.mesh
    bvh = None if local.grid is not None else prep.local.bvh
    size = power_of_two_bucket(max(n, 1), 256)
    pad = size - n
    X_pad = np.concatenate([X_np - origin, np.broadcast_to(X_np[:1] - origin, (pad, 3)) if n else
                            np.zeros((pad, 3))])
    area_pad = np.concatenate([area_np, np.zeros(pad)])
    plane_local = EmissionPlane.covering(local, prep.to_local(L_np))
    out = _trace_points(local, bvh, jnp.asarray(prep.to_local(L_np), dtype), jnp.asarray(X_pad, dtype),
                        jnp.asarray(tuple(plane_local), dtype), jnp.asarray(receiver_z - origin[2], dtype),
                        jnp.asarray(eta, dtype), jnp.asarray(intensity, dtype), jnp.asarray(area_pad, dtype))
    Y, flux, T, t, valid, cos_i = (np.asarray(x)[:n] for x in out)
    return PhotonHits(Y.astype(np.float64) + origin[:2], flux.astype(np.float64), T.astype(np.float64),
                      t.astype(np.float64), valid, cos_i.astype(np.float64))


def photon_irradiance(mesh: SurfaceMesh | PreparedSurface, L, *, intensity: float, eta: float = 1.333,
                      receiver: ReceiverGrid, n_photons: int, seed: int = 0,
                      sigma_t: float = 0.0, chunk: int = 1 << 16, progress=None) -> PhotonMap:
    """Brute-force caustic irradiance on `receiver` from a point light at `L` or a directional
    light (module docstring).

    Args:
        mesh: the refractive surface; the light must be above it.
        L: `(3,)` light position, or a `Directional(direction)` (surface/lights.py).
        intensity: radiant intensity `I_e` (W/sr); for a `Directional`, the irradiance
            on a plane perpendicular to its rays (W/m^2).
        eta: `eta_in / eta_out`.
        receiver: the binning grid on the plane `z = receiver.z` (below the surface).
        n_photons: photons emitted through the emission plane (exactly this many).
        seed: `jax.random` seed; chunk `i` uses `fold_in(key, i)`.
        sigma_t: Beer-Lambert extinction in the medium (1/m).
        chunk: most photons traced per jitted call (fewer `n_photons`: one call of the
            power of two above it, at least 256; a new size compiles once).
        progress: optional callable `progress(done, total)`, called after each chunk; a
            progress bar is drawn on a terminal in any case (`caustics_jax.runtime.progress`).

    Traced in the mesh's dtype; binned in float64.
    """
    if not isinstance(mesh, SurfaceMesh | PreparedSurface):  # as solve and irradiance take it
        raise ValueError(f"mesh must be a caustics_jax.SurfaceMesh or PreparedSurface, got {type(mesh).__name__}")
    prep = prepare(mesh)
    mesh = prep.mesh
    receiver = ReceiverGrid.check(receiver)
    check_fits("receiver (z, x0, x1, y0, y1)", receiver[:5], mesh.dtype)  # traced in the mesh's dtype
    n_photons = check_int("n_photons", n_photons, 1, MAX_PHOTONS)  # 0 photons estimate nothing
    chunk = check_int("chunk", chunk, 1, 2**24)
    seed = check_int("seed", seed, 0, 2**32 - 1)
    intensity = check_fits("intensity", check_real("intensity", intensity, 0), mesh.dtype)
    eta = check_fits("eta", check_eta(eta), mesh.dtype, positive=True)
    sigma_t = check_fits("sigma_t", check_real("sigma_t", sigma_t, 0), mesh.dtype)
    if progress is not None and not callable(progress):
        raise ValueError(f"progress must be None or a callable progress(done, total), got {progress!r}")
    at_infinity = isinstance(L, Directional)
    L_np = L if at_infinity else check_points("L", L, mesh.dtype)
    if not at_infinity and L_np.shape != (3,):
        raise ValueError(f"L must be one point of shape (3,) or a Directional, got {L_np.shape}")
    EmissionPlane.covering(mesh, L_np)  # the light above the surface (the message in the caller's frame)
    if receiver.z >= float(np.min(np.asarray(mesh.vertices)[:, 2])):
        raise ValueError(f"the receiver plane (receiver.z = {receiver.z}) must lie below the surface")
    shape = (receiver.ny, receiver.nx)
    # Traced in the frame of `prep.local` (a far mesh moved near the origin,
    # `frames.local_origin`), binned in the receiver's.
    origin = prep.origin
    mesh = prep.local.mesh
    dtype = mesh.dtype
    L_np = L_np if at_infinity else prep.to_local(L_np)
    plane = EmissionPlane.covering(mesh, L_np)
    light = L.direction if isinstance(L, Directional) else L_np
    bvh = None if mesh.grid is not None else prep.local.bvh  # built once per mesh (`prepare`)
    chunk = min(chunk, power_of_two_bucket(n_photons, 256))
    n_chunks = -(-n_photons // chunk)
    key = jax.random.PRNGKey(seed)
    E = np.zeros(receiver.nx * receiver.ny)
    E2 = np.zeros_like(E)
    hits = np.zeros(receiver.nx * receiver.ny, np.int64)
    args = (jnp.asarray(light, dtype), jnp.asarray(tuple(plane), dtype), jnp.asarray(receiver.z - origin[2], dtype),
            jnp.asarray(eta, dtype), jnp.asarray(sigma_t, dtype), jnp.asarray(intensity, dtype),
            jnp.asarray(n_photons, dtype))
    with progress_bar(total=n_photons, desc="photons", unit="photon", unit_scale=True) as bar:
        for i in range(n_chunks):
            count = min(chunk, n_photons - i * chunk)
            Y, w, valid = (np.asarray(x) for x in _trace_chunk(
                mesh, bvh, jax.random.fold_in(key, i), *args, jnp.int32(count), chunk=chunk,
                at_infinity=at_infinity))
            cell, inside = receiver.cells(Y, valid, origin)
            cell, w = cell[inside], w[inside].astype(np.float64)
            E += np.bincount(cell, w, E.size)
            E2 += np.bincount(cell, w * w, E.size)
            hits += np.bincount(cell, minlength=E.size)
            bar.update(count)
            if progress is not None:
                progress(i * chunk + count, n_photons)
    area = receiver.cell_area
    return PhotonMap(irradiance=(E / area).reshape(shape), stderr=(np.sqrt(E2) / area).reshape(shape),
                     hits=hits.reshape(shape), n_photons=n_photons, receiver=receiver)
