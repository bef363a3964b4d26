// edge_intersections: seed 001 eq. 22-24 corrected (math.md §3), cj_edge_intersections and
// cj_solve_quadratic in common.glsl.
void cj_run(inout Record r) { cj_edge_intersections(r.coef, r.t, r.valid); }
