// conic_coefficients: seed 001 eq. 10-12 (math.md §2), cj_conic_coefficients in common.glsl.
void cj_run(inout Record r) { cj_conic_coefficients(r.V, r.N, r.P, r.L, r.coef); }
