// Distance correction factor D = |L'_perp x L'_par| by ray differentials (seed 001 eq. 26-33),
// with the signs measured in transport/differentials.py (ray_differential_D): eq. 28 negated,
// eq. 31 with -eta, n_s' from the barycentrics of M' (MATH.md §6). valid = 0 and D = 0 where
// the Python kernel reports invalid (thresholds sqrt(eps) of float32).

// (a, b) with x = a E1 + b E2 by the 2x2 Gram system, det from |E1 x E2|^2 (no cancellation).
vec2 cj_edge_coordinates(vec3 E1, vec3 E2, vec3 x) {
    float g11 = dot(E1, E1), g12 = dot(E1, E2), g22 = dot(E2, E2);
    float r1 = dot(E1, x), r2 = dot(E2, x);
    vec3 c = cross(E1, E2);
    float det = dot(c, c);
    float inv = det > 0.0 ? 1.0 / det : 0.0;
    return vec2((g22 * r1 - g12 * r2) * inv, (g11 * r2 - g12 * r1) * inv);
}

float cj_safe_inv(float y, bool ok) { return ok ? 1.0 / y : 0.0; }

void cj_ray_differential_D(vec3 V[3], vec3 N[3], vec3 P, vec3 L, vec2 ab, float eta, out float D, out uint valid) {
    vec3 M, n_s, w_P, w_L;
    bool degenerate = cj_path_vectors(V, N, P, L, ab, M, n_s, w_P, w_L);
    float tiny = sqrt(CJ_EPS);
    vec3 E1 = V[1] - V[0];
    vec3 E2 = V[2] - V[0];
    float d_P = cj_norm(P - M);                                   // eq. 26
    float d_L = cj_norm(L - M);                                   // eq. 27
    vec3 n_g = cj_safe_normalize(cross(E1, E2));
    float n_len = cj_norm(cj_barycentric_point(N, ab));
    float cos_g = dot(w_P, n_g), cos_P = dot(w_P, n_s), cos_L = dot(w_L, n_s);
    float k = (1.0 - eta) * (1.0 + eta) + (eta * cos_P) * (eta * cos_P);
    bool ok_g = abs(cos_g) > tiny;
    bool ok_L = cos_L > tiny;
    bool tri_ok = cj_norm(cross(E1, E2)) > tiny * cj_norm(E1) * cj_norm(E2);
    bool ok = !degenerate && tri_ok && ok_g && ok_L && cos_P < 0.0 && k > 0.0;

    vec3 W[2];
    cj_orthonormal_frame(w_P, W[0], W[1]);  // (w_perp, w_par)
    float mu = cos_L + eta * cos_P;                               // eq. 29
    vec3 L_d[2];
    for (int j = 0; j < 2; ++j) {
        vec3 M_d = -d_P * (W[j] - cj_safe_inv(cos_g, ok_g) * dot(W[j], n_g) * w_P);  // eq. 28, negated
        vec2 ab_d = cj_edge_coordinates(E1, E2, M_d);
        vec3 n_tilde_d = ab_d.x * (N[1] - N[0]) + ab_d.y * (N[2] - N[0]);
        vec3 n_s_d = (n_tilde_d - dot(n_s, n_tilde_d) * n_s) * cj_safe_inv(n_len, n_len > 0.0);
        float mu_d = (eta * eta * cos_P * cj_safe_inv(cos_L, ok_L) + eta)
                     * (dot(W[j], n_s) + dot(w_P, n_s_d));          // eq. 30
        vec3 w_L_d = -eta * W[j] + mu_d * n_s + mu * n_s_d;         // eq. 31, -eta
        L_d[j] = M_d - dot(M_d, w_L) * w_L + d_L * w_L_d;           // eq. 32
    }
    D = ok ? cj_norm(cross(L_d[0], L_d[1])) : 0.0;                  // eq. 33
    valid = ok ? 1u : 0u;
}

void cj_run(inout Record r) { cj_ray_differential_D(r.V, r.N, r.P, r.L, r.ab, r.eta, r.D, r.valid); }
