// d_factor: seed 001 eq. 26-33 with the signs of transport/differentials.py (math.md §6),
// cj_ray_differential_D in common.glsl.
void cj_run(inout Record r) { cj_ray_differential_D(r.V, r.N, r.P, r.L, r.ab, r.eta, r.D, r.valid); }
