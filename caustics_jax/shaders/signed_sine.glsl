// Signed sine f = s |r x w_L|, r = refract(-w_P, -n_s, eta) (seed 001 eq. 19-21), with the
// 'plane' orientation s = sign((r x w_L) . (PL x n_s)) the solvers use
// (objectives.signed_sine_and_status). status: 0 OK, 1 total internal reflection,
// 2 degenerate (M = P, M = L or n~ = 0; f = 0).
void cj_signed_sine(vec3 V[3], vec3 N[3], vec3 P, vec3 L, vec2 ab, float eta, out float f, out uint status) {
    vec3 M, n_s, w_P, w_L;
    bool degenerate = cj_path_vectors(V, N, P, L, ab, M, n_s, w_P, w_L);
    vec3 r = cj_refract(-w_P, -n_s, eta);
    vec3 c = cross(r, w_L);
    float s = dot(c, cross(L - P, n_s)) >= 0.0 ? 1.0 : -1.0;
    f = degenerate ? 0.0 : s * cj_norm(c);
    bool tir = dot(r, r) == 0.0;
    status = degenerate ? 2u : (tir ? 1u : 0u);
}

void cj_run(inout Record r) { cj_signed_sine(r.V, r.N, r.P, r.L, r.ab, r.eta, r.f, r.status); }
