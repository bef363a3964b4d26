"""Reference cases of the edge crossing a walk takes between faces (`mesh.cross_edge`;
barycentric.py's edge parametrisation, seed 001 eq. 3); DESIGN.md "Reference data for
shader tests".

A record holds one face's adjacency row (`neighbor[k]`, `neighbor_edge[k]` for its three
edges, as in the `faces` buffer of a scene file), the exit edge and the exit parameter;
the face index is irrelevant to the formula. Planted rows come from a real grid mesh
(consistent winding); adversarial ones are boundaries, the edge ends and edge 2, whose
parameter runs against the vertex order.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from ..runtime.precision import precision
from ..surface import scenes
from ..surface.mesh import cross_edge
from .cases import split, stack_cases
from .records import CASES
from .registry import register


class _Adjacency(NamedTuple):
    """The two adjacency arrays `cross_edge` reads, one row per record."""

    neighbors: jnp.ndarray
    neighbor_edge: jnp.ndarray
    dtype: jnp.dtype


def _gen_cross_edge(rng, n):
    n_pl, n_rand = split(n)
    nb = rng.integers(-1, 4096, (n_rand, 3))
    rand = {"edge": rng.integers(0, 3, n_rand), "t": rng.uniform(0, 1, n_rand), "neighbor": nb,
            "neighbor_edge": np.where(nb >= 0, rng.integers(0, 3, (n_rand, 3)), -1)}
    with precision("float64"):
        mesh = scenes.wavy_pool(64, dtype="float64").surface
    faces = rng.integers(0, mesh.faces.shape[0], n_pl)
    planted = {"edge": rng.integers(0, 3, n_pl), "t": rng.uniform(0, 1, n_pl),
               "neighbor": np.asarray(mesh.neighbors)[faces], "neighbor_edge": np.asarray(mesh.neighbor_edge)[faces]}
    k = np.array([0, 1, 2, 2, 2, 0, 1, 1])
    adv = {"edge": k, "t": np.array([0.0, 1.0, 0.0, 1.0, 0.5, 0.25, 0.75, 0.5]),
           "neighbor": np.array([[7, 8, 9], [-1, -1, 5], [3, 4, -1], [1, 2, 3], [1, 2, 3], [-1, 2, 3], [1, 2, 3],
                                 [0, -1, 0]]),
           "neighbor_edge": np.array([[2, 1, 0], [-1, -1, 2], [0, 1, -1], [0, 1, 2], [2, 2, 2], [-1, 0, 1],
                                      [2, 0, 1], [1, -1, 2]])}
    return stack_cases([(rand, CASES["random"]), (planted, CASES["planted"]), (adv, CASES["adversarial"])])


@register("cross_edge", equations="edge crossing into the neighbour: t = 0 at vertex k, the shared edge runs "
          "the other way there (seed 001 eq. 3 edge parametrisation, math.md §3)", reference=cross_edge,
          inputs={"edge": "int", "t": "float", "neighbor": "int[3]", "neighbor_edge": "int[3]"},
          outputs={"next_face": "int", "next_edge": "int", "next_t": "float", "next_ab": "vec2"},
          generate=_gen_cross_edge)
def _eval_cross_edge(x):
    t = x["t"]
    adj = _Adjacency(x["neighbor"].astype(jnp.int32), x["neighbor_edge"].astype(jnp.int32), t.dtype)
    face = jnp.arange(t.shape[0], dtype=jnp.int32)  # record i holds face i's row
    g, k, t_next, ab = cross_edge(adj, face, x["edge"].astype(jnp.int32), t)
    return {"next_face": g, "next_edge": k, "next_t": t_next, "next_ab": ab}
