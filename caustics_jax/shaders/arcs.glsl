// Arcs of the coplanarity conic inside one triangle (seed 001 §3.4.3-3.4.4, math.md §2-3;
// caustics_jax/curve/arcs.py): the pencil of lines through a curve point parametrises the curve by
// the line's angle phi, measured from the travel direction tau towards perp; orientation
// picks perp's sense so that the curve ahead has phi in (0, pi), increasing along it, and the
// first edge crossing ahead is the edge root of smallest phi (settles seed 001 Fig. 5c).

// float32 values of the testbed's constants, rounded once from float64 (a float32 expression
// like 8.0 * sqrt(CJ_EPS) could round differently on a device).
const float CJ_PI_2 = 1.5707964;                 // pi / 2
const float CJ_SQRT_EPS = 3.4526698e-04;         // sqrt(eps)
const float CJ_ENTRY_GAP = 2.7621358e-03;        // 8 sqrt(eps): the entry point recomputed
const float CJ_ON_TANGENT = 1.1920929e-04;       // 1e3 eps
const float CJ_VERTEX_ZERO = 1024.0;             // arcs.VERTEX_ZERO: vertex values read as zero
const vec2 CJ_INWARD[3] = vec2[3](vec2(0.0, 1.0), vec2(-1.0, -1.0), vec2(1.0, 0.0));  // inward edge normals

// atan2 with numpy's values at zeros (atan(y, x) is undefined at (0, 0) in GLSL): +-0 for
// x >= +0, +-pi for x <= -0 (sign of y), +-pi/2 on the y axis.
float cj_atan2(float y, float x) {
    if (y == 0.0) {
        bool x_negative = x < 0.0 || (x == 0.0 && floatBitsToInt(x) < 0);
        return x_negative ? (floatBitsToInt(y) < 0 ? -CJ_PI : CJ_PI) : y;
    }
    if (x == 0.0) return y > 0.0 ? CJ_PI_2 : -CJ_PI_2;
    return atan(y, x);
}

float cj_norm2(vec2 v) { return sqrt(dot(v, v)); }

// Unit travel direction and the sigma-signed normal perp at curve point e (arcs.orientation):
// the curve bends towards -sign(c2) grad, c2 = tau^T S2 tau; perp points to that side.
void cj_orientation(float coef[6], vec2 e, vec2 tau_in, out vec2 tau, out vec2 perp) {
    tau = tau_in / max(cj_norm2(tau_in), CJ_TINY);
    float A = coef[0], B = coef[1], C = coef[2];
    vec2 t = cj_conic_tangent(coef, e);
    vec2 grad = vec2(t.y, -t.x);  // half the gradient (u, v)
    float c2 = A * (tau.x * tau.x) + B * (tau.y * tau.y) + C * tau.x * tau.y;
    vec2 bend = -sign(c2) * grad;
    float crs = tau.x * bend.y - tau.y * bend.x;
    float sigma = crs < 0.0 ? -1.0 : 1.0;
    perp = sigma * vec2(-tau.y, tau.x);
}

// The conic's edge roots and their barycentrics (arcs.edge_roots), edge-major (2 k + j).
void cj_edge_roots(float coef[6], out float t[6], out uint valid[6], out vec2 ab[6]) {
    cj_edge_intersections(coef, t, valid);
    for (int i = 0; i < 6; ++i) ab[i] = cj_edge_barycentric(i / 2, t[i]);
}

// The pencil angle in [0, pi) of the curve point e + v seen from the curve point e in the
// frame (tau, perp) (arcs.pencil_angle); dist = |v|, scale the magnitude of both points'
// barycentrics. On the tangent line itself (a straight curve), and for a point whose offset
// across the tangent is below the barycentrics' absolute rounding (64 eps of their
// magnitude: the sign of `across` is noise there, that of `along` is not), ahead comes
// first, behind last.
float cj_pencil_angle(vec2 v, vec2 tau, vec2 perp, float dist, float scale) {
    float along = dot(v, tau), across = dot(v, perp);
    float phi = cj_atan2(across, along);
    phi = phi < 0.0 ? phi + CJ_PI : phi;  // the cutting line's angle, in [0, pi)
    bool on_tangent = abs(across) <= CJ_ON_TANGENT * dist || abs(across) <= 64.0 * CJ_EPS * scale;
    return on_tangent ? (along > 0.0 ? CJ_EPS * dist : CJ_PI) : phi;
}

// The two points where the conic crosses the face's boundary, from the signs of the conic at
// the three vertices and two edge quadratics (arcs.boundary_crossings; seed 001 eq. 12 at the
// vertices: F, A + D + F, B + E + F). Returns clear: all three values beyond VERTEX_ZERO eps
// of the largest coefficient and not of one sign, the edge whose ends agree holding no pair
// of roots (its quadratic's extremum off the edge or on its ends' side of zero), one root on
// each other edge. Then the curve in the face is one arc between the two roots.
bool cj_boundary_crossings(float coef[6], out int edges[2], out float t[2], out vec2 ab[2]) {
    float big = max(max(max(abs(coef[0]), abs(coef[1])), max(abs(coef[2]), abs(coef[3]))),
                    max(abs(coef[4]), abs(coef[5])));
    float zero = CJ_VERTEX_ZERO * CJ_EPS * big;
    vec3 values = vec3(cj_conic_value(coef, vec2(0.0, 0.0)), cj_conic_value(coef, vec2(1.0, 0.0)),
                       cj_conic_value(coef, vec2(0.0, 1.0)));  // V0, V1, V2
    bool nonzero = abs(values.x) > zero && abs(values.y) > zero && abs(values.z) > zero;
    bvec3 pos = greaterThan(values, vec3(0.0));
    bvec3 differs = bvec3(pos.x != pos.y, pos.y != pos.z, pos.x != pos.z);  // edges 0, 1, 2
    int third = !differs.x ? 0 : (!differs.y ? 1 : (!differs.z ? 2 : 0));  // argmin
    int ka = third == 2 ? 0 : third + 1, kb = third == 0 ? 2 : third - 1;  // (third + 1, + 2) % 3
    vec3 q0 = cj_edge_quadratic(coef, 0), q1 = cj_edge_quadratic(coef, 1), q2 = cj_edge_quadratic(coef, 2);
    vec3 q = third == 0 ? q0 : (third == 1 ? q1 : q2);
    float t_star = -q.y / (q.x != 0.0 ? 2.0 * q.x : 1.0);
    float extremum = q.z + q.y * t_star / 2.0;
    bool pair = q.x != 0.0 && t_star > 0.0 && t_star < 1.0 && extremum * sign(q.z) <= zero;
    vec2 ra, rb;
    bvec2 va, vb;
    cj_edge_quadratic_roots(ka == 0 ? q0 : (ka == 1 ? q1 : q2), ra, va);
    cj_edge_quadratic_roots(kb == 0 ? q0 : (kb == 1 ? q1 : q2), rb, vb);
    edges[0] = ka;
    edges[1] = kb;
    t[0] = va.x ? ra.x : ra.y;
    t[1] = vb.x ? rb.x : rb.y;
    ab[0] = cj_edge_barycentric(ka, t[0]);
    ab[1] = cj_edge_barycentric(kb, t[1]);
    return nonzero && any(differs) && !pair && va.x != va.y && vb.x != vb.y;
}

// The exit of the arc that entered the face through entry_edge at entry_t (arcs.sign_test_exit):
// of cj_boundary_crossings' two, the one that is not the entry; clear also needs the entry
// edge to be one of them with its root within 8 sqrt(eps) of entry_t. Where clear,
// cj_next_crossing returns the same exit.
bool cj_sign_test_exit(float coef[6], int entry_edge, float entry_t, out int edge, out float t_x, out vec2 ab_x) {
    int edges[2];
    float t[2];
    vec2 ab[2];
    bool clear = cj_boundary_crossings(coef, edges, t, ab);
    bool entry_a = edges[0] == entry_edge;
    bool is_entry = (entry_a || edges[1] == entry_edge) && abs((entry_a ? t[0] : t[1]) - entry_t) < CJ_ENTRY_GAP;
    edge = entry_a ? edges[1] : edges[0];
    t_x = entry_a ? t[1] : t[0];
    ab_x = entry_a ? ab[1] : ab[0];
    return clear && is_entry;
}

// The first edge root met travelling along the conic from e in direction tau
// (arcs.next_crossing): the candidate of smallest pencil angle. Never a candidate: on the
// entry edge, the root nearest the entry parameter when within 8 sqrt(eps) of it (the entry
// point, recomputed here). Candidates only when no other root is left: roots within 8 eps
// (relative to the barycentrics' magnitude) of e, the same point (a vertex root reported on
// two edges); a root farther than that is a real exit however close (float32: a curve
// clipping a corner 1e-5 from a vertex). On the tangent line itself (a straight curve), and
// for a root whose offset across the tangent is below the barycentrics' absolute rounding
// (64 eps of their magnitude: the sign of `across` is noise there, that of `along` is not),
// ahead comes first, behind last.
bool cj_next_crossing(float t[6], uint valid[6], vec2 ab[6], vec2 e, vec2 tau, vec2 perp, int entry_edge,
                      float entry_t, out int edge, out float t_x, out vec2 ab_x, out float phi_x) {
    float gap[6];
    float min_gap = CJ_INF;
    for (int i = 0; i < 6; ++i) {
        gap[i] = (i / 2 == entry_edge && valid[i] != 0u) ? abs(t[i] - entry_t) : CJ_INF;
        min_gap = min(min_gap, gap[i]);
    }
    bool allowed[6], cand[6];
    float dist[6], scale[6];
    bool any_cand = false;
    for (int i = 0; i < 6; ++i) {
        vec2 v = ab[i] - e;
        dist[i] = cj_norm2(v);
        scale[i] = (abs(ab[i].x) + abs(ab[i].y)) + (abs(e.x) + abs(e.y));
        allowed[i] = valid[i] != 0u && !(gap[i] == min_gap && gap[i] < CJ_ENTRY_GAP);
        cand[i] = allowed[i] && dist[i] > 8.0 * CJ_EPS * scale[i];
        any_cand = any_cand || cand[i];
    }
    int best = 0;
    float best_phi = CJ_INF;
    for (int i = 0; i < 6; ++i) {
        float phi = cj_pencil_angle(ab[i] - e, tau, perp, dist[i], scale[i]);
        phi = (any_cand ? cand[i] : allowed[i]) ? phi : CJ_INF;
        if (phi < best_phi) {  // strict: the first of equal angles, as argmin
            best_phi = phi;
            best = i;
        }
    }
    edge = best / 2;
    t_x = t[best];
    ab_x = ab[best];
    phi_x = best_phi;
    return !isinf(best_phi);
}

// A start point e on an edge, travelling out of the triangle across that edge at once:
// the exit is that edge's root at e (angle 0), not the next root in pencil order
// (arcs.leaving_at_start). Returns whether it replaced the crossing.
bool cj_leaving_at_start(float t[6], uint valid[6], vec2 ab[6], vec2 e, vec2 tau, inout int edge, inout float t_x,
                         inout vec2 ab_x, inout float phi_x) {
    for (int i = 0; i < 6; ++i) {
        float dist = cj_norm2(ab[i] - e);
        float scale = (abs(ab[i].x) + abs(ab[i].y)) + (abs(e.x) + abs(e.y));
        if (valid[i] != 0u && dist <= 8.0 * CJ_EPS * scale && dot(CJ_INWARD[i / 2], tau) < 0.0) {
            edge = i / 2;
            t_x = t[i];
            ab_x = ab[i];
            phi_x = 0.0;
            return true;
        }
    }
    return false;
}

// The conic point nearest q along the gradient direction at q (arcs.project_to_conic).
vec2 cj_project_to_conic(float coef[6], vec2 q) {
    vec2 t = cj_conic_tangent(coef, q);
    vec2 n = vec2(t.y, -t.x);
    n = n / max(cj_norm2(n), CJ_TINY);
    float A = coef[0], B = coef[1], C = coef[2], D = coef[3], E = coef[4];
    float q2 = A * (n.x * n.x) + B * (n.y * n.y) + C * n.x * n.y;
    float q1 = (2.0 * A * q.x + C * q.y + D) * n.x + (2.0 * B * q.y + C * q.x + E) * n.y;
    vec2 h;
    bvec2 ok;
    cj_solve_quadratic(q2, q1, cj_conic_value(coef, q), h, ok);
    h = vec2(ok.x ? h.x : CJ_INF, ok.y ? h.y : CJ_INF);
    float h_min = abs(h.x) < abs(h.y) ? h.x : h.y;
    return q + (isinf(h_min) ? 0.0 : h_min) * n;
}

// The curve point cut by the line through anchor at pencil angle phi (arcs.pencil_point).
vec2 cj_pencil_point(float coef[6], vec2 anchor, vec2 tau, vec2 perp, float phi, out bool ok) {
    vec2 d = cos(phi) * tau + sin(phi) * perp;
    return cj_conic_second_intersection(coef, anchor, d, ok);
}

// Strictly opposite signs; a sign change of both f ('plane') and g ('line'): a root, not an
// orientation flip (arcs.opposite, arcs.root_between).
bool cj_opposite(float f1, float f2) { return sign(f1) * sign(f2) < 0.0; }

bool cj_root_between(float f1, float g1, float f2, float g2) {
    return cj_opposite(f1, f2) && cj_opposite(g1, g2);
}

// ab in the closed triangle up to 64 eps (arcs.inside).
bool cj_inside(vec2 ab) {
    const float slack = 64.0 * CJ_EPS;
    return ab.x >= -slack && ab.y >= -slack && ab.x + ab.y <= 1.0 + slack;
}
