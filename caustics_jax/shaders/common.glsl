// Helpers shared by the kernel ports and the scene shader (the walk): GLSL 450 versions of
// caustics_jax/math/geometry.py, barycentric.py, conic.py, objectives.py and
// transport/differentials.py. Each formula exists once in GLSL too: a kernel file holds
// only its cj_run. Every function mirrors the Python kernel line by line, so a difference
// in a conformance run points at one line.

const float CJ_EPS = 1.1920929e-7;  // float32 machine epsilon, jnp.finfo(float32).eps
const float CJ_PI = 3.14159265358979;
const float CJ_INF = 1.0 / 0.0;
const float CJ_TINY = 1.1754944e-38;  // jnp.finfo(float32).tiny, the smallest normal float32

float cj_safe_sqrt(float x) { return x > 0.0 ? sqrt(x) : 0.0; }

// ---------------------------------------------------------------- geometry (math.md §1)

// A finite number > 0 (NaN and inf fail).
bool cj_finite_positive(float x) { return x > 0.0 && !isinf(x); }

// geometry.norm / safe_normalize: |v|, and v / |v| or the zero vector (never NaN).
float cj_norm(vec3 v) { return cj_safe_sqrt(dot(v, v)); }

vec3 cj_safe_normalize(vec3 v) {
    float len = cj_norm(v);
    return len > 0.0 ? v * (1.0 / len) : vec3(0.0);
}

// geometry.refraction_k: refract's k = 1 - eta^2 (1 - cos^2) = cos_t^2 (seed 002 eq. 3.1),
// regrouped as (1 - eta)(1 + eta) + (eta cos)^2, free of both cancellations; from |eta| = 16
// (above every physical ratio) 1 - eta (eta sin^2), sin^2 = (1 - cos)(1 + cos), which
// neither cancels nor overflows to NaN (inf - inf had made eta = 1e30 a transmitted ray).
float cj_refraction_k(float cos_i, float eta) {
    if (abs(eta) < 16.0) return (1.0 - eta) * (1.0 + eta) + (eta * cos_i) * (eta * cos_i);
    return 1.0 - eta * (eta * ((1.0 - cos_i) * (1.0 + cos_i)));
}

// GLSL refract semantics (math.md §1; seed 002 eq. 3.1-3.2), with the Python kernel's
// cancellation-free k. Total internal reflection (k < 0) returns the zero vector.
vec3 cj_refract(vec3 I, vec3 N, float eta) {
    float cos_i = dot(N, I);
    float k = cj_refraction_k(cos_i, eta);
    if (!(k >= 0.0)) return vec3(0.0);  // TIR, or NaN input: no ray (the kernel's k >= 0 mask)
    return eta * I - (eta * cos_i + cj_safe_sqrt(k)) * N;
}

// Exact unpolarised dielectric Fresnel reflectance, the F of seed 001 eq. 25
// (geometry.fresnel_reflectance): R = (r_s^2 + r_p^2) / 2, R = 1 under TIR and at grazing.
float cj_fresnel_reflectance(float cos_i, float eta) {
    if (isnan(cos_i)) return 1.0;  // clamp(NaN) is undefined in GLSL; the kernel's NaN lane gives 1
    cos_i = clamp(abs(cos_i), 0.0, 1.0);
    float cos_t2 = cj_refraction_k(cos_i, eta);  // 1 - sin_t^2
    float cos_t = cj_safe_sqrt(cos_t2);
    float den_s = eta * cos_i + cos_t;
    float den_p = cos_i + eta * cos_t;
    if (!(cos_t2 > 0.0 && den_s > 0.0 && den_p > 0.0)) return 1.0;
    float r_s = (eta * cos_i - cos_t) / den_s;
    float r_p = (cos_i - eta * cos_t) / den_p;
    return (r_s * r_s + r_p * r_p) / 2.0;
}

// Throughput after the water (kernels.culling.throughput; seed 001 eq. 25's T A, seed 003):
// beta = T(cos_i, eta) exp(-sigma_t max(t, 0)), T = 1 - R the exact Fresnel transmittance.
float cj_throughput(float cos_i, float t, float eta, float sigma_t) {
    // clear water (sigma_t = 0) attenuates nothing, also over an infinite t (0 inf is NaN)
    float optical_depth = sigma_t > 0.0 ? sigma_t * max(t, 0.0) : 0.0;
    return (1.0 - cj_fresnel_reflectance(cos_i, eta)) * exp(-optical_depth);
}

// Seed 003's cull test (kernels.culling.energy_cull): kept where energy >= threshold; NaN culled.
bool cj_energy_kept(float energy, float threshold) { return energy >= threshold; }

// ------------------------------------------------------ barycentrics (seed 001 eq. 3, 6-8)

// M = V0 + a (V1 - V0) + b (V2 - V0), same for the unnormalised interpolated normal n~.
vec3 cj_barycentric_point(vec3 X[3], vec2 ab) {
    return X[0] + ab.x * (X[1] - X[0]) + ab.y * (X[2] - X[0]);
}

// barycentric.edge_barycentric: (a, b) at parameter t on edge k (0: (t, 0); 1: (1 - t, t);
// 2: (0, t)), and edge_param_from_vertex_order (t = 0 at vertex k; an involution).
vec2 cj_edge_barycentric(int k, float t) {
    return k == 0 ? vec2(t, 0.0) : (k == 1 ? vec2(1.0 - t, t) : vec2(0.0, t));
}

float cj_edge_param_from_vertex_order(int k, float t) { return k == 2 ? 1.0 - t : t; }

// mesh.cross_edge from one face's adjacency row: cross edge k at parameter t into the face
// across it (-1 on a boundary) and its entry edge k_next. Consistent winding runs the shared
// edge the other way there: the point at s from vertex k sits at 1 - s from vertex k_next.
// On a boundary (or an invalid face) t and ab stay the exit point's.
int cj_cross_edge_row(bool valid_face, int edge, float t, int neighbor[3], int neighbor_edge[3],
                      out int k_next, out float t_out, out vec2 ab) {
    int k = clamp(edge, 0, 2);
    int g = valid_face ? neighbor[k] : -1;
    k_next = g >= 0 ? neighbor_edge[k] : -1;
    float s = cj_edge_param_from_vertex_order(k, t);
    float t_next = cj_edge_param_from_vertex_order(max(k_next, 0), 1.0 - s);
    bool crossed = g >= 0;
    t_out = crossed ? t_next : t;
    ab = cj_edge_barycentric(crossed ? k_next : k, t_out);
    return g;
}

// barycentric.barycentric_coordinates: (a, b) with x = a E1 + b E2 by the 2x2 Gram system,
// det from |E1 x E2|^2 (Lagrange's identity, no cancellation on thin triangles).
vec2 cj_edge_coordinates(vec3 E1, vec3 E2, vec3 x) {
    float g11 = dot(E1, E1), g12 = dot(E1, E2), g22 = dot(E2, E2);
    float r1 = dot(E1, x), r2 = dot(E2, x);
    vec3 c = cross(E1, E2);
    float det = dot(c, c);
    float inv = det > 0.0 ? 1.0 / det : 0.0;
    return vec2((g22 * r1 - g12 * r2) * inv, (g11 * r2 - g12 * r1) * inv);
}

// objectives.path_vectors: M, n_s, w_P = (P - M)/|P - M|, w_L = (L - M)/|L - M| (math.md §1).
bool cj_path_vectors(vec3 V[3], vec3 N[3], vec3 P, vec3 L, vec2 ab,
                     out vec3 M, out vec3 n_s, out vec3 w_P, out vec3 w_L) {
    M = cj_barycentric_point(V, ab);
    vec3 n_tilde = cj_barycentric_point(N, ab);
    vec3 PM = P - M;
    vec3 LM = L - M;
    n_s = cj_safe_normalize(n_tilde);
    w_P = cj_safe_normalize(PM);
    w_L = cj_safe_normalize(LM);
    // degenerate: a zero length, or one that is not finite (an inf P had read as a root, OK)
    return !(cj_finite_positive(cj_norm(n_tilde)) && cj_finite_positive(cj_norm(PM))
             && cj_finite_positive(cj_norm(LM)));
}

// objectives.orthonormal_frame: branchless basis (s, t) of Duff et al. 2017.
void cj_orthonormal_frame(vec3 n, out vec3 s, out vec3 t) {
    float sgn = n.z >= 0.0 ? 1.0 : -1.0;
    float a = -1.0 / (sgn + n.z);
    float b = n.x * n.y * a;
    s = vec3(1.0 + sgn * n.x * n.x * a, sgn * b, -sgn * n.x);
    t = vec3(b, sgn + n.y * n.y * a, -n.y);
}

// ------------------------------------------------------ the coplanarity conic (math.md §2-3)

// Conic coefficients A..F of the coplanarity constraint (seed 001 eq. 10-12; math.md §2):
// K = N^T Q with columns of N: n1 - n0, n2 - n0, n0 (eq. 7) and of Q: PL x V0V1,
// PL x V0V2, PL x PV0 (eq. 10); A = K11, B = K22, C = K12 + K21, D = K13 + K31,
// E = K23 + K32, F = K33.
void cj_conic_coefficients(vec3 V[3], vec3 N[3], vec3 P, vec3 L, out float coef[6]) {
    vec3 PL = L - P;
    vec3 Ncol[3] = vec3[3](N[1] - N[0], N[2] - N[0], N[0]);
    vec3 Qcol[3] = vec3[3](cross(PL, V[1] - V[0]), cross(PL, V[2] - V[0]), cross(PL, V[0] - P));
    float K[3][3];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) K[i][j] = dot(Ncol[i], Qcol[j]);
    coef[0] = K[0][0];
    coef[1] = K[1][1];
    coef[2] = K[0][1] + K[1][0];
    coef[3] = K[0][2] + K[2][0];
    coef[4] = K[1][2] + K[2][1];
    coef[5] = K[2][2];
}

// A a^2 + B b^2 + C a b + D a + E b + F (seed 001 eq. 12; conic.conic_value).
float cj_conic_value(float coef[6], vec2 ab) {
    float a = ab.x, b = ab.y;
    return coef[0] * a * a + coef[1] * b * b + coef[2] * a * b + coef[3] * a + coef[4] * b + coef[5];
}

// Conic tangent (-v, u) in barycentric space (seed 001 eq. 13-15 with the symmetric part
// S = (K + K^T)/2, math.md §2: the paper's K^T is the gradient only for symmetric K).
vec2 cj_conic_tangent(float coef[6], vec2 ab) {
    float A = coef[0], B = coef[1], C = coef[2], D = coef[3], E = coef[4];
    float u = A * ab.x + C / 2.0 * ab.y + D / 2.0;
    float v = C / 2.0 * ab.x + B * ab.y + E / 2.0;
    return vec2(-v, u);
}

// Real roots of q2 t^2 + q1 t + q0, ascending, cancellation-free (conic.solve_quadratic,
// Numerical Recipes §5.6): coefficients scaled by a power of two, q = -(q1 + sign(q1)
// sqrt(disc)) / 2, roots q / q2 and q0 / q; linear, tangent and all-zero cases masked.
void cj_solve_quadratic(float q2, float q1, float q0, out vec2 roots, out bvec2 valid) {
    float scale = max(max(abs(q2), abs(q1)), abs(q0));
    // a coefficient not finite: no roots (conic.solve_quadratic; frexp of inf or NaN is
    // undefined in GLSL, and GLSL's max of a NaN is either operand)
    bool nonzero = cj_finite_positive(scale) && !isnan(q2 + q1 + q0);
    int e;
    frexp(nonzero ? scale : 1.0, e);
    float a = ldexp(q2, -e), b = ldexp(q1, -e), c = ldexp(q0, -e);
    bool linear = a == 0.0;
    float a_safe = linear ? 1.0 : a;
    float disc = b * b - 4.0 * a * c;
    float rounding = 8.0 * CJ_EPS * (b * b + abs(4.0 * a * c));
    bool tangent = nonzero && !linear && abs(disc) <= rounding;
    bool two = nonzero && !linear && disc > rounding;
    bool one_linear = nonzero && linear && b != 0.0;
    float sign_b = b >= 0.0 ? 1.0 : -1.0;
    float q = -(b + sign_b * sqrt(two ? disc : 1.0)) / 2.0;
    float q_safe = two ? q : 1.0;
    float r1 = q / a_safe, r2 = c / q_safe;
    float root0 = two ? min(r1, r2)
                      : (tangent ? -b / (2.0 * a_safe) : (one_linear ? -c / (b != 0.0 ? b : 1.0) : 0.0));
    float root1 = two ? max(r1, r2) : 0.0;
    valid = bvec2(two || tangent || one_linear, two);
    roots = vec2(valid.x ? root0 : 0.0, valid.y ? root1 : 0.0);
}

// Quadratic (q2, q1, q0) in the edge parameter t of edge k (seed 001 eq. 22-24, corrected in
// math.md §3; conic.edge_quadratics). Edge 0: b = 0, t = a; edge 1: (a, b) = (1 - t, t);
// edge 2: a = 0, t = b.
vec3 cj_edge_quadratic(float coef[6], int k) {
    float A = coef[0], B = coef[1], C = coef[2], D = coef[3], E = coef[4], F = coef[5];
    if (k == 0) return vec3(A, D, F);                      // b = 0 (eq. 23 prints A a^2 + C a + F)
    if (k == 1) return vec3(A + B - C, C + E - 2.0 * A - D, A + D + F);  // a = 1 - b (eq. 24)
    return vec3(B, E, F);                                  // a = 0 (eq. 22 prints B b^2 + D b + F)
}

// One edge's roots in [-tol, 1 + tol] clamped to [0, 1], ascending, tol = 64 eps (the Python
// kernel's float32 default, export.EDGE_TOL; conic.edge_quadratic_roots).
void cj_edge_quadratic_roots(vec3 quad, out vec2 t, out bvec2 valid) {
    const float tol = 64.0 * CJ_EPS;
    vec2 roots;
    bvec2 ok;
    cj_solve_quadratic(quad.x, quad.y, quad.z, roots, ok);
    for (int j = 0; j < 2; ++j) {
        bool keep = ok[j] && roots[j] >= -tol && roots[j] <= 1.0 + tol;
        t[j] = keep ? clamp(roots[j], 0.0, 1.0) : 0.0;
        valid[j] = keep;
    }
}

// Intersections of the conic with the three triangle edges (seed 001 eq. 22-24, corrected
// in math.md §3; conic.edge_intersections). Outputs edge-major: t[2 e + k], valid[2 e + k].
void cj_edge_intersections(float coef[6], out float t[6], out uint valid[6]) {
    for (int k = 0; k < 3; ++k) {
        vec2 roots;
        bvec2 ok;
        cj_edge_quadratic_roots(cj_edge_quadratic(coef, k), roots, ok);
        for (int j = 0; j < 2; ++j) {
            t[2 * k + j] = roots[j];
            valid[2 * k + j] = ok[j] ? 1u : 0u;
        }
    }
}

// Second point where the line ab0 + s d meets the conic, ab0 on it (seed 001 §3.4.3; the
// pencil of lines through a curve point, conic.conic_second_intersection): of the two roots
// of Q(ab0 + s d) the one of larger magnitude; invalid unless there are two.
vec2 cj_conic_second_intersection(float coef[6], vec2 ab0, vec2 d, out bool ok) {
    float A = coef[0], B = coef[1], C = coef[2], D = coef[3], E = coef[4];
    float q2 = A * d.x * d.x + B * d.y * d.y + C * d.x * d.y;
    float grad_a = 2.0 * A * ab0.x + C * ab0.y + D;
    float grad_b = 2.0 * B * ab0.y + C * ab0.x + E;
    float q1 = grad_a * d.x + grad_b * d.y;
    vec2 s;
    bvec2 valid;
    cj_solve_quadratic(q2, q1, cj_conic_value(coef, ab0), s, valid);
    ok = valid.x && valid.y;
    float far_s = (ok && abs(s.x) > abs(s.y)) ? s.x : s.y;
    return ab0 + (ok ? far_s : 0.0) * d;
}

// ------------------------------------------------------ objectives (seed 001 eq. 19-21)

// Signed sine f = s |r x w_L|, r = refract(-w_P, -n_s, eta) (seed 001 eq. 19-21;
// objectives.signed_sine_and_status) from the path vectors, in both orientations:
// 'plane' s = sign((r x w_L) . (PL x n_s)) and 'line' s = sign((r x w_L) . (PL x PM)).
// status: 0 OK, 1 total internal reflection, 2 degenerate (M = P, M = L or n~ = 0; f = 0).
void cj_signed_sines(vec3 M, vec3 n_s, vec3 w_P, vec3 w_L, bool degenerate, vec3 P, vec3 L, float eta,
                     out vec3 r, out float f_plane, out float f_line, out uint status) {
    r = cj_refract(-w_P, -n_s, eta);
    vec3 c = cross(r, w_L);
    float len = cj_norm(c);
    float s_plane = dot(c, cross(L - P, n_s)) >= 0.0 ? 1.0 : -1.0;
    float s_line = dot(c, cross(L - P, M - P)) >= 0.0 ? 1.0 : -1.0;
    f_plane = degenerate ? 0.0 : s_plane * len;
    f_line = degenerate ? 0.0 : s_line * len;
    bool tir = dot(r, r) == 0.0;
    status = degenerate ? 2u : (tir ? 1u : 0u);
}

// The 'plane' orientation the solvers use.
void cj_signed_sine(vec3 V[3], vec3 N[3], vec3 P, vec3 L, vec2 ab, float eta, out float f, out uint status) {
    vec3 M, n_s, w_P, w_L, r;
    bool degenerate = cj_path_vectors(V, N, P, L, ab, M, n_s, w_P, w_L);
    float g;
    cj_signed_sines(M, n_s, w_P, w_L, degenerate, P, L, eta, r, f, g, status);
}

// objectives.bracket_objective at one point: f ('plane'), status (ObjectiveStatus: 0 OK,
// 1 TIR, 2 degenerate, 3 BACKWARD: the refracted ray points away from L, where f ~ sin(pi)
// also vanishes, or P lies beyond the shading plane at M, outside refract's domain), and g
// ('line'). A true root flips both f and g (arcs.root_between).
void cj_bracket_objective(vec3 V[3], vec3 N[3], vec3 P, vec3 L, vec2 ab, float eta,
                          out float f, out uint status, out float g) {
    vec3 M, n_s, w_P, w_L, r;
    bool degenerate = cj_path_vectors(V, N, P, L, ab, M, n_s, w_P, w_L);
    cj_signed_sines(M, n_s, w_P, w_L, degenerate, P, L, eta, r, f, g, status);
    if (status == 0u && (dot(r, w_L) <= 0.0 || dot(P - M, n_s) >= 0.0)) status = 3u;
}

// ------------------------------------------------------ transport (seed 001 eq. 25-33)

// Distance correction factor D = |L'_perp x L'_par| by ray differentials (seed 001 eq. 26-33),
// with the signs measured in transport/differentials.py (ray_differential_D): eq. 28 negated,
// eq. 31 with -eta, n_s' from the barycentrics of M' (math.md §6). valid = 0 and D = 0 where
// the Python kernel reports invalid (thresholds sqrt(eps) of float32).
float cj_safe_inv(float y, bool ok) { return ok ? 1.0 / y : 0.0; }

// normalized: D / d_L^2 = |(L'_perp / d_L) x (L'_par / d_L)| instead (ray_differential_D(...,
// normalized=True); math.md §9): finite for a far light, and a directional light's limit.
void cj_ray_differential(vec3 V[3], vec3 N[3], vec3 P, vec3 L, vec2 ab, float eta, bool normalized,
                         out float D, out uint valid) {
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
    float k = cj_refraction_k(cos_P, eta);
    bool ok_g = abs(cos_g) > tiny;
    bool ok_L = cos_L > tiny;
    bool tri_ok = cj_norm(cross(E1, E2)) > tiny * cj_norm(E1) * cj_norm(E2);
    // eta > 0 (finite: checked with D below): a traced eta outside its domain is an invalid lane
    bool ok = !degenerate && tri_ok && ok_g && ok_L && cos_P < 0.0 && k > 0.0 && eta > 0.0;

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
        if (normalized)                                             // eq. 32 / d_L
            L_d[j] = (M_d - dot(M_d, w_L) * w_L) * cj_safe_inv(d_L, d_L > 0.0) + w_L_d;
        else
            L_d[j] = M_d - dot(M_d, w_L) * w_L + d_L * w_L_d;       // eq. 32
    }
    D = cj_norm(cross(L_d[0], L_d[1]));                             // eq. 33
    ok = ok && cj_finite_positive(D);  // overflow beyond the scale band is no valid D
    D = ok ? D : 0.0;
    valid = ok ? 1u : 0u;
}

void cj_ray_differential_D(vec3 V[3], vec3 N[3], vec3 P, vec3 L, vec2 ab, float eta, out float D, out uint valid) {
    cj_ray_differential(V, N, P, L, ab, eta, false, D, valid);
}

// Irradiance at P through the refraction point ab (seed 001 eq. 25 with the factors of
// math.md §6; transport.contribution.path_irradiance): E = eta^2 T A cos(theta_P) I_e / D,
// T = 1 - R the Fresnel transmittance from the light's side (cos = w_L . n_s, ratio 1/eta),
// A = exp(-sigma_t |P - M|), cos(theta_P) = max(-w_P . n_P, 0). E = 0 where D is invalid.
// Formed as (I_e / d_L^2) / (D / d_L^2), finite for far lights (a directional light's lanes
// carry its point at the limit distance, math.md §9). valid = 0 where D is invalid.
float cj_path_irradiance(vec3 V[3], vec3 N[3], vec3 P, vec3 L, vec2 ab, float eta, float intensity,
                         vec3 receiver_normal, float sigma_t, out uint valid) {
    vec3 M, n_s, w_P, w_L;
    cj_path_vectors(V, N, P, L, ab, M, n_s, w_P, w_L);
    float D_n;
    uint D_valid;
    cj_ray_differential(V, N, P, L, ab, eta, true, D_n, D_valid);
    float d_L = cj_norm(L - M);
    float T = 1.0 - cj_fresnel_reflectance(dot(w_L, n_s), 1.0 / eta);
    float cos_P = max(-dot(w_P, cj_safe_normalize(receiver_normal)), 0.0);
    float A = exp(-sigma_t * cj_norm(P - M));
    bool ok = D_valid != 0u && D_n > 0.0;
    valid = ok ? 1u : 0u;
    float E_perp = intensity / (d_L > 0.0 ? d_L * d_L : 1.0);
    return ok ? eta * eta * T * A * cos_P * E_perp / D_n : 0.0;
}

// ------------------------------------------------------ screen space (seed 004 §3.3)

// Cross-bilateral weight w = w_z w_pos (seed 004 eq. 21-23; kernels.bilateral.bilateral_weight):
// w_z = 1 / (|z_p - z_q| + eps) (eq. 22; Alg. 4 line 22 uses eps = 1),
// w_pos = 1 / (1 + 10 d.d / delta^2), d = pos_p - pos_q (eq. 23), evaluated as
// delta'^2 / (delta'^2 + 10 d'.d') with d and delta divided by their largest magnitude m:
// delta^2 alone underflows (delta = 1e-23, p = q: 0/0) or overflows (delta = |d| = 1e30).
float cj_bilateral_weight(float z_p, float z_q, vec3 pos_p, vec3 pos_q, float delta, float eps) {
    vec3 d = pos_p - pos_q;
    float w_z = 1.0 / (abs(z_p - z_q) + max(eps, CJ_TINY));  // eps floored, as the kernel inside jit
    float m = max(abs(delta), max(abs(d.x), max(abs(d.y), abs(d.z))));
    if (m > 0.0) {
        d /= m;
        delta /= m;
    }
    float delta2 = delta * delta;
    float den = delta2 + 10.0 * dot(d, d);  // in [1, 11] unless delta = d = 0
    float w_pos = den > 0.0 ? delta2 / den : 1.0;
    return w_z * w_pos;
}
