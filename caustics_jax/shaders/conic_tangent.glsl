// conic_tangent: seed 001 eq. 13-15 with S = (K + K^T)/2 (math.md §2), cj_conic_tangent in common.glsl.
void cj_run(inout Record r) { r.t = cj_conic_tangent(r.coef, r.ab); }
