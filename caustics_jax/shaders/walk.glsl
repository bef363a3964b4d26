// The curve walk of seed 001 §3.4 (caustics_jax/solvers/walk.py, per lane): follow the
// coplanarity conic from M0 to a zero of the signed sine f (eq. 19-21, 'plane' orientation;
// bracketed with the 'line' orientation g as well, so that an orientation flip is no root).
//
// 1. First triangle: the conic's tangent at M0 gives two directions; for each, the next
//    crossing along the curve (pencil of lines through M0) and a near point just off M0.
//    A sign change between them is refined at once; else the walk goes out of total internal
//    reflection first, then towards the smaller |f|. No edge crossing at all: an ellipse in
//    the triangle (§3.4.4), sampled through the pencil for a sign change.
// 2. Walk (§3.4.3): cross the exit edge into the neighbour, orient the tangent inward, find
//    the next crossing, evaluate f at the exit (at the entry it is the previous exit's, carried
//    in the state: one evaluation per point); bracket where it changes sign. An arc
//    from a transmitting point into TIR (or back) is searched towards the onset of TIR.
// 3. Refine ("dichotomy"): cut the arc by the conic's normal line through a chord point at
//    Illinois false position (or the midpoint), or, where that cut leaves the bracket, by the
//    line through the anchor at the interpolated pencil angle.
// A walk that started without a bracket and fails turns back once and walks the other way
// within the same step budget. FOUND exactly when |f| <= tol at the returned point.

const int CJ_WALK = 0, CJ_BISECT = 1, CJ_DONE = 2;
// Status codes (the manifest's status table) and ObjectiveStatus codes.
const uint CJ_FOUND = 0u, CJ_NO_CROSSING = 1u, CJ_S_TIR = 2u, CJ_LEFT_MESH = 3u, CJ_MAX_STEPS = 4u,
           CJ_UNRESOLVED_ELLIPSE = 5u, CJ_DEGENERATE = 6u, CJ_LOST_CURVE = 7u, CJ_NOT_CONVERGED = 8u;
const uint CJ_OK = 0u, CJ_TIR = 1u, CJ_DEG = 2u, CJ_BACKWARD = 3u;
const float CJ_DELTA0 = 1.1920929e-03;  // 1e4 eps: the near points' offset from M0

struct WalkState {
    int mode;
    uint status;
    int face;
    int exit_k;
    float exit_t;
    vec2 exit_ab;
    float f_exit;   // f, its status and its 'line' sign g at the exit: the next face's entry
    uint st_exit;
    float g_exit;
    vec2 anchor;
    vec2 tau;
    vec2 perp;   // tau rotated +90 deg, times the bend sense sigma
    float phi_lo, phi_hi, f_lo, f_hi;
    vec2 ab_lo, ab_hi;  // bracket ends as points (for the chord cut)
    int side;     // Illinois: which end was replaced last (-1 lo, +1 hi, 0 none)
    int tir_end;  // TIR search: which end is totally reflecting (-1 lo, +1 or 2 hi, 0 none)
    vec2 best_ab;
    float best_f;
    int steps;
    int crossed;
};

struct Frame {
    vec3 V[3];
    vec3 N[3];
    float coef[6];
};

Frame cj_frame(int face, vec3 P, vec3 L) {
    Frame fr;
    cj_triangle(face, fr.V, fr.N);
    cj_conic_coefficients(fr.V, fr.N, P, L, fr.coef);
    return fr;
}

void cj_objective(Frame fr, vec3 P, vec3 L, vec2 ab, float eta, out float f, out uint st, out float g) {
    cj_bracket_objective(fr.V, fr.N, P, L, ab, eta, f, st, g);
}

// -w_P . n_s at ab: the cosine of incidence on P's side (walk_start._cos_at_P).
float cj_cos_at_P(Frame fr, vec3 P, vec3 L, vec2 ab) {
    vec3 M, n_s, w_P, w_L;
    cj_path_vectors(fr.V, fr.N, P, L, ab, M, n_s, w_P, w_L);
    return -dot(w_P, n_s);
}

// One direction of travel from M0 (walk_start.first_triangle's `direction`).
struct Direction {
    bool ok;
    int k;
    float t;
    vec2 ab;
    float phi;
    vec2 tau, perp;
    float phi_s;  // pencil angle of the near point
    vec2 near;
    float room;
};

// The near point of a direction whose exit is known (walk_start.first_triangle's `direction`).
Direction cj_direction_near(float coef[6], vec2 ab0, Direction d) {
    d.room = cj_norm2(d.ab - ab0);
    float delta = d.ok ? min(CJ_DELTA0, 0.25 * d.room) : CJ_DELTA0;
    d.near = cj_project_to_conic(coef, ab0 + delta * d.tau);
    vec2 v = d.near - ab0;
    float phi_s = cj_atan2(dot(v, d.perp), dot(v, d.tau));
    d.phi_s = min(max(phi_s, 0.0), d.ok ? d.phi / 2.0 : CJ_PI_2);
    return d;
}

// The exit by the pencil order over six edge roots (cj_next_crossing, cj_leaving_at_start).
Direction cj_direction(float coef[6], float rt[6], uint rv[6], vec2 rab[6], vec2 ab0, vec2 t0) {
    Direction d;
    cj_orientation(coef, ab0, t0, d.tau, d.perp);
    d.ok = cj_next_crossing(rt, rv, rab, ab0, d.tau, d.perp, -1, 0.0, d.k, d.t, d.ab, d.phi);
    d.ok = cj_leaving_at_start(rt, rv, rab, ab0, d.tau, d.k, d.t, d.ab, d.phi) || d.ok;
    return cj_direction_near(coef, ab0, d);
}

// The exit as the boundary crossing of smaller pencil angle (cj_boundary_crossings; walk's
// lean first triangle): dist and scale of the two crossings from ab0.
Direction cj_direction_lean(float coef[6], int edges[2], float t[2], vec2 ab[2], float dist[2], float scale[2],
                            vec2 ab0, vec2 t0) {
    Direction d;
    cj_orientation(coef, ab0, t0, d.tau, d.perp);
    float phi0 = cj_pencil_angle(ab[0] - ab0, d.tau, d.perp, dist[0], scale[0]);
    float phi1 = cj_pencil_angle(ab[1] - ab0, d.tau, d.perp, dist[1], scale[1]);
    int i = phi1 < phi0 ? 1 : 0;  // the first of equal angles, as argmin
    d.ok = true;
    d.k = edges[i];
    d.t = t[i];
    d.ab = ab[i];
    d.phi = i == 1 ? phi1 : phi0;
    return cj_direction_near(coef, ab0, d);
}

// The initial state of one of the two walks from M0 (walk_start.start_states's `build`).
WalkState cj_build(bool walk_m, int face, vec2 ab0, bool found, float tol, Direction dp, Direction dm,
                   float f0, uint st0, bool singular, float fp, float fm, uint stp, uint stm, float gp, float gm,
                   uint st_np, uint st_nm,
                   float fsp, float fsm, bool br_p, bool br_m, bool use_m_bracket, bool is_ellipse, bool ellipse_bracket,
                   vec2 tau_e, vec2 perp_e, float e_phi_lo, float e_phi_hi, float e_f_lo, float e_f_hi, vec2 e_ab_lo,
                   vec2 e_ab_hi, out bool can_flip) {
    WalkState s;
    bool bracket = is_ellipse ? ellipse_bracket : (br_p || br_m);
    bool use_m = use_m_bracket || (!(br_p || br_m) && walk_m);
    // No sign change, and the arc of the walk direction runs into TIR (or BACKWARD, walk_start.py's
    // first_triangle): search it towards the onset first; without a root there the walk
    // goes on (tir_end = 2).
    bool lost_m = stm == CJ_TIR || stm == CJ_BACKWARD, lost_p = stp == CJ_TIR || stp == CJ_BACKWARD;
    bool tir_arc = walk_m ? (dm.ok && st_nm == CJ_OK && lost_m) : (dp.ok && st_np == CJ_OK && lost_p);
    // ... or out of it: the near point totally reflecting (or BACKWARD), the exit
    // transmitting; the root between the onset and the exit (tir_end = -1).
    bool lost_nm = st_nm == CJ_TIR || st_nm == CJ_BACKWARD, lost_np = st_np == CJ_TIR || st_np == CJ_BACKWARD;
    bool tir_out = walk_m ? (dm.ok && lost_nm && stm == CJ_OK) : (dp.ok && lost_np && stp == CJ_OK);
    bool search = !is_ellipse && !(br_p || br_m) && (tir_arc || tir_out);
    s.tau = is_ellipse ? tau_e : (use_m ? dm.tau : dp.tau);
    s.perp = is_ellipse ? perp_e : (use_m ? dm.perp : dp.perp);
    s.phi_lo = is_ellipse ? e_phi_lo : (use_m ? dm.phi_s : dp.phi_s);
    s.phi_hi = is_ellipse ? e_phi_hi : (use_m ? dm.phi : dp.phi);
    s.f_lo = is_ellipse ? e_f_lo : (use_m ? fsm : fsp);
    s.f_hi = is_ellipse ? e_f_hi : (use_m ? fm : fp);
    s.ab_lo = is_ellipse ? e_ab_lo : (use_m ? dm.near : dp.near);
    s.ab_hi = is_ellipse ? e_ab_hi : (use_m ? dm.ab : dp.ab);
    s.exit_k = walk_m ? dm.k : dp.k;
    s.exit_t = walk_m ? dm.t : dp.t;
    s.exit_ab = walk_m ? dm.ab : dp.ab;
    s.f_exit = walk_m ? fm : fp;
    uint st_exit = walk_m ? stm : stp;
    s.st_exit = st_exit;
    s.g_exit = walk_m ? gm : gp;

    uint status = CJ_FOUND;
    int mode = (bracket || search) ? CJ_BISECT : CJ_WALK;
    // A walk may start inside TIR: it walks on until f is defined, so only a degenerate exit stops it.
    if (!bracket && st_exit == CJ_DEG) { mode = CJ_DONE; status = CJ_DEGENERATE; }
    if (is_ellipse && !ellipse_bracket) { mode = CJ_DONE; status = CJ_UNRESOLVED_ELLIPSE; }
    bool at_m0 = abs(f0) <= tol && st0 == CJ_OK;  // M0 itself is a solution
    if (at_m0) { mode = CJ_DONE; status = CJ_FOUND; }
    // A singular conic at a solution M0 does not matter (every point is coplanar): M0 stays FOUND.
    if ((singular && !at_m0) || st0 == CJ_DEG) { mode = CJ_DONE; status = CJ_DEGENERATE; }
    if (!found) { mode = CJ_DONE; status = CJ_NO_CROSSING; }
    bool searching = search && mode == CJ_BISECT;
    can_flip = (mode == CJ_WALK || searching) && dp.ok && dm.ok;
    s.mode = mode;
    s.status = status;
    s.face = face;
    s.anchor = ab0;
    s.side = 0;
    s.tir_end = searching ? (tir_arc ? 2 : -1) : 0;
    s.best_ab = ab0;
    s.best_f = f0;
    s.steps = 0;
    s.crossed = 0;
    return s;
}

// The two initial states from M0 (walk_start.first_triangle, walk_start.start_states): `state` walks the chosen way,
// `other` the other way; can_flip says whether that second way exists.
void cj_first_triangle(vec3 P, vec3 L, int face, vec2 ab0, bool found, float eta, float tol, int n_ellipse,
                       out bool can_flip, out WalkState state, out WalkState other) {
    Frame fr = cj_frame(face, P, L);
    vec2 t0 = cj_conic_tangent(fr.coef, ab0);
    bool singular = dot(t0, t0) == 0.0;
    // The exits from the vertex signs (cj_boundary_crossings) where they decide and M0 is
    // neither crossing; else the pencil order over six edge roots (walk_start.first_triangle).
    int b_edge[2];
    float b_t[2], b_dist[2], b_scale[2];
    vec2 b_ab[2];
    bool clear = cj_boundary_crossings(fr.coef, b_edge, b_t, b_ab) && !singular;
    for (int j = 0; j < 2; ++j) {
        b_dist[j] = cj_norm2(b_ab[j] - ab0);
        b_scale[j] = (abs(b_ab[j].x) + abs(b_ab[j].y)) + (abs(ab0.x) + abs(ab0.y));
        clear = clear && b_dist[j] > 8.0 * CJ_EPS * b_scale[j];
    }
    Direction dp, dm;
    if (clear) {
        dp = cj_direction_lean(fr.coef, b_edge, b_t, b_ab, b_dist, b_scale, ab0, t0);
        dm = cj_direction_lean(fr.coef, b_edge, b_t, b_ab, b_dist, b_scale, ab0, -t0);
    } else {
        float rt[6];
        uint rv[6];
        vec2 rab[6];
        cj_edge_roots(fr.coef, rt, rv, rab);
        dp = cj_direction(fr.coef, rt, rv, rab, ab0, t0);
        dm = cj_direction(fr.coef, rt, rv, rab, ab0, -t0);
    }
    vec2 tau_e, perp_e;
    cj_orientation(fr.coef, ab0, t0, tau_e, perp_e);

    float f0, fp, fm, fsp, fsm, g0, gp, gm, gsp, gsm;
    uint st0, stp, stm, st_np, st_nm;
    cj_objective(fr, P, L, ab0, eta, f0, st0, g0);
    cj_objective(fr, P, L, dp.ab, eta, fp, stp, gp);
    cj_objective(fr, P, L, dm.ab, eta, fm, stm, gm);
    cj_objective(fr, P, L, dp.near, eta, fsp, st_np, gsp);
    cj_objective(fr, P, L, dm.near, eta, fsm, st_nm, gsm);
    // No room for a near point: f is continuous, so the exit's sign stands for the arc.
    if (dp.ok && dp.room < 4.0 * CJ_DELTA0) { fsp = fp; gsp = gp; }
    if (dm.ok && dm.room < 4.0 * CJ_DELTA0) { fsm = fm; gsm = gm; }

    bool br_p = dp.ok && cj_root_between(fsp, gsp, fp, gp) && stp == CJ_OK && st_np == CJ_OK;
    bool br_m = dm.ok && cj_root_between(fsm, gsm, fm, gm) && stm == CJ_OK && st_nm == CJ_OK;
    bool use_m_bracket = br_m && (!br_p || dm.phi < dp.phi);
    // Without a bracket: out of total internal reflection first (towards the larger cosine
    // at P's side), else towards the smaller |f|.
    bool tirp = stp == CJ_TIR, tirm = stm == CJ_TIR;
    float cos_p = cj_cos_at_P(fr, P, L, dp.ab), cos_m = cj_cos_at_P(fr, P, L, dm.ab);
    bool prefer_m = tirp != tirm ? tirp : (tirp ? cos_m > cos_p : abs(fm) < abs(fp));

    // Ellipse inside the triangle (§3.4.4): the whole curve through the pencil at M0, from the
    // near point of +t0 to the near point of -t0, first sign change.
    bool is_ellipse = !dp.ok && !dm.ok;
    bool ellipse_bracket = false;
    float e_phi_lo = 0.0, e_phi_hi = 0.0, e_f_lo = 0.0, e_f_hi = 0.0;
    vec2 e_ab_lo = vec2(0.0), e_ab_hi = vec2(0.0);
    if (is_ellipse) {
        vec2 v = dm.near - ab0;
        float phi_nm = cj_atan2(dot(v, perp_e), dot(v, tau_e));
        phi_nm = phi_nm < 0.0 ? phi_nm + CJ_PI : phi_nm;
        float prev_phi = dp.phi_s, prev_f = fsp, prev_g = gsp;
        vec2 prev_ab = dp.near;
        bool prev_ok = st_np == CJ_OK;
        for (int i = 1; i <= n_ellipse; ++i) {
            float phi, f, g;
            vec2 ab;
            bool ok;
            uint st;
            if (i < n_ellipse) {
                phi = (CJ_PI * float(i)) / float(n_ellipse);
                ab = cj_pencil_point(fr.coef, ab0, tau_e, perp_e, phi, ok);
                cj_objective(fr, P, L, ab, eta, f, st, g);
            } else {
                phi = phi_nm;
                ab = dm.near;
                f = fsm;
                g = gsm;
                st = st_nm;
                ok = true;
            }
            ok = ok && st == CJ_OK;
            if (cj_root_between(prev_f, prev_g, f, g) && prev_ok && ok) {
                ellipse_bracket = true;
                e_phi_lo = prev_phi;
                e_phi_hi = phi;
                e_f_lo = prev_f;
                e_f_hi = f;
                e_ab_lo = prev_ab;
                e_ab_hi = ab;
                break;
            }
            prev_phi = phi;
            prev_f = f;
            prev_g = g;
            prev_ab = ab;
            prev_ok = ok;
        }
    }

    bool walk_m = dm.ok && (!dp.ok || prefer_m);
    state = cj_build(walk_m, face, ab0, found, tol, dp, dm, f0, st0, singular, fp, fm, stp, stm, gp, gm, st_np, st_nm,
                     fsp, fsm, br_p, br_m, use_m_bracket, is_ellipse, ellipse_bracket, tau_e, perp_e, e_phi_lo,
                     e_phi_hi, e_f_lo, e_f_hi, e_ab_lo, e_ab_hi, can_flip);
    bool unused;
    other = cj_build(!walk_m, face, ab0, found, tol, dp, dm, f0, st0, singular, fp, fm, stp, stm, gp, gm, st_np,
                     st_nm,
                     fsp, fsm, br_p, br_m, use_m_bracket, is_ellipse, ellipse_bracket, tau_e, perp_e, e_phi_lo,
                     e_phi_hi, e_f_lo, e_f_hi, e_ab_lo, e_ab_hi, unused);
}

// Cross into face g at e (entry edge k_in); bracket if f changes sign on its arc, else
// schedule the next crossing (walk_steps._walk_geometry and _walk_update).
WalkState cj_walk_step(WalkState s, vec3 P, vec3 L, float eta, float tol) {
    bool from_m0 = s.phi_hi == 0.0;  // this crossing enters the neighbour at M0 (cj_leaving_at_start)
    int k_in;
    float t_in;
    vec2 e;
    int g = cj_cross_edge(s.face, s.exit_k, s.exit_t, k_in, t_in, e);
    s.steps += 1;
    if (g < 0) {  // a boundary edge: the walk ends at the exit point
        s.mode = CJ_DONE;
        s.status = CJ_LEFT_MESH;
        s.best_ab = s.exit_ab;
        s.best_f = s.f_exit;
        return s;
    }
    Frame fr = cj_frame(g, P, L);
    vec2 t = cj_conic_tangent(fr.coef, e);
    float side = dot(t, CJ_INWARD[clamp(k_in, 0, 2)]);
    vec2 tau, perp;
    cj_orientation(fr.coef, e, side < 0.0 ? -t : t, tau, perp);
    int k;
    float tt, phi;
    vec2 ab;
    // The exit from the vertex signs (cj_sign_test_exit); where they do not decide, the exact
    // construction over six edge roots (walk_steps._lean_walk_branch, the EXACT phase).
    bool ok = cj_sign_test_exit(fr.coef, k_in, t_in, k, tt, ab);
    if (ok) {
        vec2 v = ab - e;
        phi = cj_pencil_angle(v, tau, perp, cj_norm2(v), (abs(ab.x) + abs(ab.y)) + (abs(e.x) + abs(e.y)));
    } else {
        float rt[6];
        uint rv[6];
        vec2 rab[6];
        cj_edge_roots(fr.coef, rt, rv, rab);
        ok = cj_next_crossing(rt, rv, rab, e, tau, perp, k_in, t_in, k, tt, ab, phi);
    }

    // At the entry, f is the previous exit's (the same curve point: the two faces' normals
    // agree on their shared edge); only the exit is evaluated (walk_steps._walk_update).
    float f_e = s.f_exit, g_e = s.g_exit, fx, gx;
    uint st_e = s.st_exit, stx;
    cj_objective(fr, P, L, ab, eta, fx, stx, gx);
    bool e_ok = st_e == CJ_OK, x_ok = stx == CJ_OK;
    bool found_e = e_ok && abs(f_e) <= tol;
    bool found_x = ok && x_ok && abs(fx) <= tol;
    // Entering the neighbour at M0 itself (exit angle 0, cj_leaving_at_start): g is undefined
    // on the line PL, so a sign change of f alone brackets (walk_steps._walk_update).
    bool bracket = ok && e_ok && x_ok && (cj_root_between(f_e, g_e, fx, gx) || (from_m0 && cj_opposite(f_e, fx)));
    bool lost = !ok || side == 0.0;
    // An arc from a transmitting point to a totally reflecting one (or back) may hold a root
    // between the transmitting end and the onset of TIR: search it towards the onset.
    // Into BACKWARD: the same search, and the walk goes on without a root (2; walk.py).
    int tir_end = (ok && e_ok && stx == CJ_TIR) ? 1 : ((ok && e_ok && stx == CJ_BACKWARD) ? 2
                  : ((ok && (st_e == CJ_TIR || st_e == CJ_BACKWARD) && x_ok) ? -1 : 0));

    s.mode = (bracket || tir_end != 0) ? CJ_BISECT : CJ_WALK;
    if (lost) { s.mode = CJ_DONE; s.status = CJ_LOST_CURVE; }
    if (found_x) { s.mode = CJ_DONE; s.status = CJ_FOUND; }
    if (found_e) { s.mode = CJ_DONE; s.status = CJ_FOUND; }
    bool at_x = found_x && !found_e;
    s.best_ab = at_x ? ab : e;
    s.best_f = at_x ? fx : f_e;
    s.face = g;
    s.exit_k = k;
    s.exit_t = tt;
    s.exit_ab = ab;
    s.f_exit = fx;
    s.st_exit = stx;
    s.g_exit = gx;
    s.anchor = e;
    s.tau = tau;
    s.perp = perp;
    s.phi_lo = 0.0;
    s.phi_hi = phi;
    s.f_lo = f_e;
    s.f_hi = fx;
    s.ab_lo = e;
    s.ab_hi = ab;
    s.side = 0;
    s.tir_end = tir_end;
    s.crossed += 1;
    return s;
}

// Curve point cut by the conic's normal line at lam along the chord (walk_steps._chord_point).
vec2 cj_chord_point(float coef[6], vec2 ab_lo, vec2 ab_hi, float lam, out bool ok) {
    vec2 q = ab_lo + lam * (ab_hi - ab_lo);
    vec2 p = cj_project_to_conic(coef, q);
    vec2 chord = ab_hi - ab_lo;
    float along = dot(p - ab_lo, chord);
    ok = along > 0.0 && along < dot(chord, chord);
    return p;
}

// One refinement cut of the bracketed arc (walk_steps._bisect_geometry and _bisect_update).
WalkState cj_bisect_step(WalkState s, vec3 P, vec3 L, float eta, float tol, bool illinois) {
    Frame fr = cj_frame(s.face, P, L);
    float denom = s.f_hi - s.f_lo;
    float lam = 0.5;
    if (illinois) {
        float frac = -s.f_lo / (denom != 0.0 ? denom : 1.0);  // false position, from the lo end
        lam = denom != 0.0 ? clamp(frac, 1e-6, 0.999999) : 0.5;
        lam = s.tir_end != 0 ? 0.5 : lam;  // f is 0 at a TIR end: no false position
    }
    float phi_try = s.phi_lo + lam * (s.phi_hi - s.phi_lo);
    bool ok_pencil, ok_chord;
    vec2 p_pencil = cj_pencil_point(fr.coef, s.anchor, s.tau, s.perp, phi_try, ok_pencil);
    vec2 p_chord = cj_chord_point(fr.coef, s.ab_lo, s.ab_hi, lam, ok_chord);
    // The bracketed arc lies in the triangle: a cut outside it hit another piece of the conic.
    ok_pencil = ok_pencil && cj_inside(p_pencil);
    ok_chord = ok_chord && cj_inside(p_chord);
    vec2 p = ok_chord ? p_chord : p_pencil;
    vec2 v = p - s.anchor;
    float phi = ok_chord ? cj_atan2(dot(v, s.perp), dot(v, s.tau)) : phi_try;
    bool ok = ok_pencil || ok_chord;

    float fm, gm;
    uint stm;
    cj_objective(fr, P, L, p, eta, fm, stm, gm);
    bool transmits = stm == CJ_OK;
    bool searching = s.tir_end != 0;
    bool tir_mid = searching && (stm == CJ_TIR || stm == CJ_BACKWARD);  // BACKWARD: past the onset too
    ok = ok && (transmits || tir_mid);
    bool to_hi = cj_opposite(fm, s.f_lo);  // the root lies between lo and p: p is the new hi
    // TIR search: p replaces the TIR end when it reflects too, or when f changed sign against
    // the transmitting end (then [that end, p] is a plain bracket); otherwise p replaces the
    // transmitting end, closing in on the onset of TIR.
    float f_ok_end = s.tir_end > 0 ? s.f_lo : s.f_hi;
    bool flipped = transmits && cj_opposite(fm, f_ok_end);
    bool replace_tir_end = tir_mid || flipped;
    to_hi = searching ? (s.tir_end > 0 ? replace_tir_end : !replace_tir_end) : to_hi;
    int tir_end = flipped ? 0 : s.tir_end;
    float phi_lo = to_hi ? s.phi_lo : phi, phi_hi = to_hi ? phi : s.phi_hi;
    vec2 ab_lo = to_hi ? s.ab_lo : p, ab_hi = to_hi ? p : s.ab_hi;
    float f_lo = to_hi ? s.f_lo : fm, f_hi = to_hi ? fm : s.f_hi;
    int side = s.side;
    if (illinois) {  // halve the stale end's value when the same end is kept twice
        side = searching ? 0 : (to_hi ? 1 : -1);
        f_lo = (to_hi && s.side == 1) ? f_lo / 2.0 : f_lo;
        f_hi = (!to_hi && s.side == -1) ? f_hi / 2.0 : f_hi;
    }
    bool found = ok && transmits && abs(fm) <= tol;
    // The pencil angle only measures a curved arc; on a straight one (phi = 0 to rounding)
    // the bracket is judged by its end points alone. After a chord cut phi is only derived
    // from the point (its rounding exceeds the threshold on nearly straight arcs): only a
    // pencil cut stalls in phi (walk_steps._bisect_update).
    bool curved = max(abs(phi_lo), abs(phi_hi)) > CJ_SQRT_EPS;
    bool stalled = cj_norm2(ab_hi - ab_lo) <= 4.0 * CJ_EPS * max(cj_norm2(ab_hi), 1.0)
                   || (curved && !ok_chord && abs(phi_hi - phi_lo) <= 4.0 * CJ_EPS * max(abs(phi_hi), 1e-30));
    int mode = (found || stalled || !ok) ? CJ_DONE : CJ_BISECT;
    uint status = found ? CJ_FOUND : ((stalled || !ok) ? CJ_NOT_CONVERGED : s.status);
    // A TIR search that closed in on the onset without a sign change found no root: a walk
    // into TIR ends there (tir_end 1), a walk out of it (-1) or out of the first triangle (2)
    // goes on from the arc's exit.
    bool no_root = stalled && !found && tir_end != 0;
    if (no_root) {
        mode = tir_end == 1 ? CJ_DONE : CJ_WALK;
        status = tir_end == 1 ? CJ_S_TIR : s.status;
    }
    bool better = ok && transmits && abs(fm) < abs(s.best_f);
    s.mode = mode;
    s.status = status;
    if (ok) {
        s.phi_lo = phi_lo;
        s.phi_hi = phi_hi;
        s.f_lo = f_lo;
        s.f_hi = f_hi;
        s.ab_lo = ab_lo;
        s.ab_hi = ab_hi;
        s.tir_end = tir_end;
    }
    s.side = side;
    if (better || found) {
        s.best_ab = p;
        s.best_f = fm;
    }
    s.steps += 1;
    return s;
}

// Walk one lane (walk.WalkSolver's stages and steps): the final state; MAX_STEPS when max_steps ran out.
WalkState cj_walk(vec3 P, vec3 L, int face, vec2 ab0, bool found, float eta, float tol, int max_steps,
                  bool illinois, int n_ellipse) {
    bool can_flip;
    WalkState state, other;
    cj_first_triangle(P, L, face, ab0, found, eta, tol, n_ellipse, can_flip, state, other);
    bool turned = false;
    while (state.mode != CJ_DONE && state.steps < max_steps) {
        WalkState nxt = state.mode == CJ_WALK ? cj_walk_step(state, P, L, eta, tol)
                                              : cj_bisect_step(state, P, L, eta, tol, illinois);
        if (nxt.mode == CJ_DONE && nxt.status != CJ_FOUND && can_flip && !turned) {
            other.steps = nxt.steps;  // restart from M0 the other way, same budget
            other.crossed = nxt.crossed;
            nxt = other;
            turned = true;
        }
        state = nxt;
    }
    if (state.mode != CJ_DONE) state.status = CJ_MAX_STEPS;
    return state;
}
