// signed_sine: seed 001 eq. 19-21, orientation 'plane', cj_signed_sine in common.glsl.
void cj_run(inout Record r) { cj_signed_sine(r.V, r.N, r.P, r.L, r.ab, r.eta, r.f, r.status); }
