// The one-step Newton on the half-vector constraint (caustics_jax/solvers/newton.py,
// stepping "one_step", constraint "half_vector": the testbed's strongest baseline,
// newton-hv-step), per lane: Hanika et al. 2015 (MNEE) §4.3 as Cycles' mnee_newton_solver runs
// it, with the testbed's acceptance.
//
// From M0, each iteration takes one Newton step x - beta J^-1 C(x) on the half-vector residual
// C = (h . s, h . t) (Walter et al. 2009; math.md §4), J in closed form, the 2x2 system by
// Cramer's rule, in the plane of the current triangle; the tentative point is projected back
// onto the surface along the ray from P through it, walking the adjacency from the current
// face along the step (at most 16 edges, Cycles' bounded ray hits). The step is accepted when
// the projection lands on the surface and the path there still transmits (P and L on opposite
// sides of the shading normal); then beta doubles back towards 1, else it halves, and the lane
// gives up below 1e-4 (Cycles' MNEE_MINIMUM_STEP_SIZE): LEFT_MESH where the projection ran off
// the mesh, else NOT_CONVERGED. FOUND exactly when |f| <= tol at the accepted point (the signed
// sine, 'plane', and status OK: every solver is judged by it; Cycles stops on the constraint
// norm instead, 1e-3). The first step size is the scene's initial_step: 1 takes full Newton
// steps (newton-hv-step), 0.1 is Cycles' MNEE step control (newton-hv-step-gentle).

const int CJ_MAX_PROJECTION_CROSSINGS = 16;  // newton.MAX_PROJECTION_CROSSINGS
const float CJ_MIN_BETA = 1e-4;              // newton.MIN_BETA

// objectives.half_vector_residual_and_jacobian: r = (h . s, h . t) with h = -(w_L + eta w_P)
// normalised and (s, t) Duff et al.'s frame of n_s, and its Jacobian by (a, b) in closed form
// (math.md §4): columns c0 = dr/da, c1 = dr/db, through dM = e_j, dn~ = n_j - n0,
// dw = -(I - w w^T) dM / d, dh = -(I - h h^T)(dw_L + eta dw_P) / |w_L + eta w_P|,
// dn_s = (I - n_s n_s^T) dn~ / |n~| and the frame's derivative. A vanishing length gives 0.
void cj_half_vector_jacobian(vec3 V[3], vec3 N[3], vec3 P, vec3 L, vec2 ab, float eta,
                             out vec2 r, out vec2 c0, out vec2 c1) {
    vec3 M, n_s, w_P, w_L;
    cj_path_vectors(V, N, P, L, ab, M, n_s, w_P, w_L);
    vec3 g = -(w_L + eta * w_P);
    vec3 h = cj_safe_normalize(g);
    vec3 s, t;
    cj_orthonormal_frame(n_s, s, t);
    r = vec2(dot(h, s), dot(h, t));
    float lg = cj_norm(g), lP = cj_norm(P - M), lL = cj_norm(L - M), ln = cj_norm(cj_barycentric_point(N, ab));
    float inv_g = lg > 0.0 ? 1.0 / lg : 0.0, inv_P = lP > 0.0 ? 1.0 / lP : 0.0;
    float inv_L = lL > 0.0 ? 1.0 / lL : 0.0, inv_n = ln > 0.0 ? 1.0 / ln : 0.0;
    float x = n_s.x, y = n_s.y, z = n_s.z;
    float sgn = z >= 0.0 ? 1.0 : -1.0;
    float c = -1.0 / (sgn + z);
    vec2 cols[2];
    for (int j = 0; j < 2; ++j) {
        vec3 dM = V[j + 1] - V[0], dn = N[j + 1] - N[0];
        vec3 dw_P = -(dM - dot(w_P, dM) * w_P) * inv_P;
        vec3 dw_L = -(dM - dot(w_L, dM) * w_L) * inv_L;
        vec3 dg = dw_L + eta * dw_P;
        vec3 dh = -(dg - dot(h, dg) * h) * inv_g;
        vec3 dns = (dn - dot(n_s, dn) * n_s) * inv_n;
        float dx = dns.x, dy = dns.y, dz = dns.z;
        float dc = c * c * dz;
        float db = c * (y * dx + x * dy) + x * y * dc;
        vec3 ds = vec3(sgn * (2.0 * x * c * dx + x * x * dc), sgn * db, -sgn * dx);
        vec3 dt = vec3(db, 2.0 * y * c * dy + y * y * dc, -dy);
        cols[j] = vec2(dot(dh, s) + dot(h, ds), dot(dh, t) + dot(h, dt));
    }
    c0 = cols[0];
    c1 = cols[1];
}

// newton._exit_edge: the first edge the segment ab -> ab_new leaves the triangle through
// (edge 0: b = 0, 1: a + b = 1, 2: a = 0), and the exit's edge parameter t.
int cj_exit_edge(vec2 ab, vec2 ab_new, out float t) {
    vec2 d = ab_new - ab;
    float lam[3];
    lam[0] = d.y < 0.0 ? -ab.y / d.y : CJ_INF;
    float sum = d.x + d.y;
    lam[1] = sum > 0.0 ? (1.0 - ab.x - ab.y) / sum : CJ_INF;
    lam[2] = d.x < 0.0 ? -ab.x / d.x : CJ_INF;
    int k = 0;
    for (int i = 0; i < 3; ++i) lam[i] = max(lam[i], 0.0);
    if (lam[1] < lam[k]) k = 1;
    if (lam[2] < lam[k]) k = 2;
    vec2 q = ab + min(lam[k], 1.0) * d;
    t = clamp(k == 0 ? q.x : q.y, 0.0, 1.0);
    return k;
}

// math.barycentric.ray_plane_barycentric: barycentrics where the ray from P through T meets the plane
// of triangle V (seed 001 eq. 3 solved for a, b), and whether it meets it ahead of P.
bool cj_ray_plane_barycentric(vec3 V[3], vec3 P, vec3 T, out vec2 ab) {
    vec3 E1 = V[1] - V[0], E2 = V[2] - V[0];
    vec3 n = cross(E1, E2);
    vec3 d = T - P;
    float denom = dot(n, d);
    bool ok = denom != 0.0;
    float s = ok ? dot(n, V[0] - P) / denom : 0.0;
    ab = cj_edge_coordinates(E1, E2, P + s * d - V[0]);
    return ok && s > 0.0;
}

// newton._reproject: the tentative point ab_t (in face's extended plane) projected back onto
// the surface along the ray from P through it, crossing edges from face along the step.
// Returns hit (landed inside a face); face, ab the landing; left: the walk met the boundary.
bool cj_reproject(vec3 P, inout int face, vec2 ab, vec2 ab_t, out vec2 y, out bool left, out int crossings) {
    vec3 V[3], N[3];
    cj_triangle(face, V, N);
    vec3 T = cj_barycentric_point(V, ab_t);
    vec2 x = ab;
    y = ab_t;
    bool ok = true;
    left = false;
    crossings = 0;
    while (ok && !cj_inside(y) && crossings < CJ_MAX_PROJECTION_CROSSINGS) {
        float t;
        int k = cj_exit_edge(x, y, t);
        int k_next;
        float t_next;
        vec2 e;
        int g = cj_cross_edge(face, k, t, k_next, t_next, e);
        vec3 Vg[3], Ng[3];
        cj_triangle(g, Vg, Ng);
        vec2 y_g;
        bool hit = cj_ray_plane_barycentric(Vg, P, T, y_g);
        ok = g >= 0 && hit;
        if (ok) {
            face = g;
            x = e;
            y = y_g;
        }
        left = left || g < 0;
        crossings += 1;
    }
    return ok && cj_inside(y);
}

struct NewtonState {
    int face;
    vec2 ab;
    uint status;
    bool done;
    int steps;
    int crossed;
    float beta;
};

// newton._f_at: f ('plane') and its status (objectives.bracket_objective) at ab of face.
float cj_f_at(int face, vec3 P, vec3 L, vec2 ab, float eta, out uint st) {
    vec3 V[3], N[3];
    cj_triangle(face, V, N);
    float f, g;
    cj_bracket_objective(V, N, P, L, ab, eta, f, st, g);
    return f;
}

// newton._one_step: one Newton step with step size beta, projected back onto the surface.
void cj_newton_step(vec3 P, vec3 L, float eta, float tol, inout NewtonState s) {
    vec3 V[3], N[3];
    cj_triangle(s.face, V, N);
    vec2 r, c0, c1;
    cj_half_vector_jacobian(V, N, P, L, s.ab, eta, r, c0, c1);
    float det = c0.x * c1.y - c1.x * c0.y;
    bool solvable = !isinf(det) && !isnan(det) && det != 0.0 && !any(isnan(r)) && !any(isinf(r));
    float inv = solvable ? 1.0 / det : 1.0;
    vec2 dx = solvable ? vec2(c1.y * r.x - c1.x * r.y, c0.x * r.y - c0.y * r.x) * inv : vec2(0.0);
    int face = s.face;
    vec2 ab;
    bool left;
    int crossings;
    bool hit = cj_reproject(P, face, s.ab, s.ab - s.beta * dx, ab, left, crossings);
    // The projected path must still refract: P and L on opposite sides of the shading normal.
    vec3 Vn[3], Nn[3];
    cj_triangle(face, Vn, Nn);
    vec3 M, n_s, w_P, w_L;
    bool degenerate = cj_path_vectors(Vn, Nn, P, L, ab, M, n_s, w_P, w_L);
    bool transmits = dot(n_s, w_P) * dot(n_s, w_L) < 0.0 && !degenerate;
    bool accept = solvable && hit && transmits;
    uint st;
    float f = cj_f_at(face, P, L, ab, eta, st);
    bool found = accept && abs(f) <= tol && st == CJ_OK;
    // A step that cannot move the point any more (Cycles: MNEE_MIN_PROGRESS_DISTANCE).
    bool stalled = accept && !found && length(s.beta * dx) <= 4.0 * CJ_EPS * max(length(s.ab), 1.0);
    float beta = accept ? min(1.0, 2.0 * s.beta) : s.beta / 2.0;
    bool gave_up = !accept && beta < CJ_MIN_BETA;
    if (found) s.status = CJ_FOUND;
    if (stalled || (gave_up && !left) || !solvable) s.status = CJ_NOT_CONVERGED;
    if (gave_up && left && solvable) s.status = CJ_LEFT_MESH;
    if (accept) {
        s.face = face;
        s.ab = ab;
        s.crossed += crossings;
    }
    s.done = found || stalled || gave_up || !solvable;
    s.steps += 1;
    s.beta = beta;
}

// newton.NewtonSolver (newton_init, newton_iteration, _finish): the lane's end state and f there.
NewtonState cj_newton(vec3 P, vec3 L, int face, vec2 ab0, float eta, float tol, int max_iterations, float beta0,
                      out float f_end) {
    NewtonState s;
    uint st0;
    float f0 = cj_f_at(face, P, L, ab0, eta, st0);
    bool at_m0 = abs(f0) <= tol && st0 == CJ_OK;
    s.face = face;
    s.ab = ab0;
    s.status = at_m0 ? CJ_FOUND : CJ_MAX_STEPS;
    s.done = at_m0;
    s.steps = 0;
    s.crossed = 0;
    s.beta = beta0;
    while (!s.done && s.steps < max_iterations) cj_newton_step(P, L, eta, tol, s);
    uint st_end;
    f_end = cj_f_at(s.face, P, L, s.ab, eta, st_end);
    if (s.status == CJ_MAX_STEPS && st_end == CJ_TIR) s.status = CJ_S_TIR;  // out of steps where it reflects
    if (s.status == CJ_FOUND && !(abs(f_end) <= tol)) s.status = CJ_NOT_CONVERGED;  // _solution.confirm_found
    return s;
}
