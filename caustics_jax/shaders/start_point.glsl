// Start point of a solver: the first crossing M0 of segment P -> L with the surface, the
// crossing nearest P (seed 001 §3.4.2: M0 satisfies the coplanarity constraint trivially),
// found through the face cells the testbed's start points traverse (accel/face_cells.py,
// first_hit_cells; the scene file's cell_lines, cell_faces and cell_rows buffers): a 2D DDA
// over the cells of the plane (cell_axis_u, cell_axis_v), the segment clipped to the box of
// the grid and of the surface's range along cell_axis_w (the slab), cells whose faces' height
// range the segment misses skipped, each other cell's faces tested by cj_triangle_crossing.
// A lane stops when its best crossing lies before the point where it leaves the current cell
// (no later cell can hold an earlier one), or when it leaves the slab or the grid. Cost per
// lane: the cells crossed inside the slab, times the faces listed per cell, independent of
// the face count (a heightfield grid's cells are its own, two faces each).
//
// Buffers: cj_cell_lines[] (the cell_nu + 1 lines along u, then the cell_nv + 1 along v),
// cj_cell_faces[] (row r: faces [r w, (r + 1) w), w = cell_width, -1 padding; cell (i, j) starts
// at row j nu + i) and cj_cell_rows[] (per row: the row continuing its list, and its cell's
// height range).

// crossing.triangle_crossing: the line P + s d against triangle V (Moller-Trumbore) with the
// rounding-aware tolerance of the testbed (C_ROUND = 8 times the first-order bound plus 16 eps).
// Returns inside (in the triangle within the bound), s (unclipped), s_tol, the rank (s, moved
// back by s_tol where the hit needed the tolerance) and ab projected into the closed triangle.
bool cj_triangle_crossing(vec3 P, vec3 d, vec3 V[3], out float s, out float s_tol, out float rank,
                          out vec2 ab) {
    const float c_round = 8.0;
    vec3 e1 = V[1] - V[0], e2 = V[2] - V[0];
    float len_e1 = sqrt(dot(e1, e1)), len_e2 = sqrt(dot(e2, e2));
    float V0_max = max(max(abs(V[0].x), abs(V[0].y)), abs(V[0].z));
    vec3 pvec = cross(d, e2);
    float det = dot(e1, pvec);
    float len_d = sqrt(dot(d, d));
    bool ok = abs(det) > 16.0 * CJ_EPS * len_d * len_e1 * len_e2;
    float inv = ok ? 1.0 / det : 0.0;
    vec3 tvec = P - V[0];
    vec3 qvec = cross(tvec, e1);
    float a = dot(tvec, pvec) * inv, b = dot(d, qvec) * inv;
    s = dot(e2, qvec) * inv;
    float reach = min(abs(s), 1.0);
    float P_max = max(max(abs(P.x), abs(P.y)), abs(P.z)), d_max = max(max(abs(d.x), abs(d.y)), abs(d.z));
    float delta = c_round * CJ_EPS * (max(P_max, V0_max) + reach * d_max);
    float abs_inv = abs(inv);
    float tol_a = 16.0 * CJ_EPS + delta * sqrt(dot(pvec, pvec)) * abs_inv;
    float tol_b = 16.0 * CJ_EPS + delta * len_d * len_e1 * abs_inv;
    s_tol = 16.0 * CJ_EPS + delta * len_e1 * len_e2 * abs_inv;
    bool inside = ok && a >= -tol_a && b >= -tol_b && a + b <= 1.0 + tol_a + tol_b;
    bool exact = ok && a >= 0.0 && b >= 0.0 && a + b <= 1.0;
    rank = exact ? s : s + s_tol;
    a = max(a, 0.0);
    b = max(b, 0.0);
    float total = a + b > 1.0 ? a + b : 1.0;
    ab = vec2(a / total, b / total);
    return inside;
}

// crossing.clip_to_box: segment parameters [s_in, s_out] of P + s d inside the box [lo, hi],
// within [0, s_max] (slabs with 1/d; an axis with d = 0 is inside or outside whole).
void cj_clip_to_box(vec3 P, vec3 d, vec3 lo, vec3 hi, float s_max, out float s_in, out float s_out) {
    float near_max = -CJ_INF, far_min = CJ_INF;
    for (int i = 0; i < 3; ++i) {
        bool moving = d[i] != 0.0;
        float inv = moving ? 1.0 / d[i] : 0.0;
        float t0 = (lo[i] - P[i]) * inv, t1 = (hi[i] - P[i]) * inv;
        bool inside = P[i] >= lo[i] && P[i] <= hi[i];
        float near_i = moving ? min(t0, t1) : (inside ? -CJ_INF : CJ_INF);
        float far_i = moving ? max(t0, t1) : (inside ? CJ_INF : -CJ_INF);
        near_max = max(near_max, near_i);
        far_min = min(far_min, far_i);
    }
    s_in = max(near_max, 0.0);
    s_out = min(far_min, s_max);
}

// Line k (0: u, 1: v) number i of the cells.
float cj_cell_line(int k, int i) { return cj_cell_lines[k == 0 ? i : int(cj_scene.cell_nu) + 1 + i].x; }

// The cell holding coordinate x along grid axis k: searchsorted(lines, x, 'right') - 1, clipped.
int cj_cell_of(int k, float x) {
    int n = k == 0 ? int(cj_scene.cell_nu) : int(cj_scene.cell_nv);
    int lo = 0, hi = n + 1;  // the first line above x lies in [lo, hi]
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (cj_cell_line(k, mid) <= x) lo = mid + 1; else hi = mid;
    }
    return clamp(lo - 1, 0, n - 1);
}

// face_cells._GridStep.wall: where P + s d meets the next wall along grid axis k from cell i.
float cj_cell_wall(int k, int i, ivec2 stp, float Pa, float da) {
    int n = k == 0 ? int(cj_scene.cell_nu) : int(cj_scene.cell_nv);
    if (stp[k] == 0) return CJ_INF;
    float x = cj_cell_line(k, clamp(i + (stp[k] > 0 ? 1 : 0), 0, n));
    return (x - Pa) / da;
}

// face_cells._GridStep.next_cell: where the segment leaves cell ij, the cell it enters
// (clipped into the grid), and whether it leaves the grid or the window s <= s_out instead.
float cj_next_cell(ivec2 ij, ivec2 stp, vec2 Puv, vec2 duv, float s_out, out ivec2 ij_next, out bool gone) {
    ivec2 n = ivec2(cj_scene.cell_nu, cj_scene.cell_nv);
    float s_u = cj_cell_wall(0, ij.x, stp, Puv.x, duv.x), s_v = cj_cell_wall(1, ij.y, stp, Puv.y, duv.y);
    float s_leave = min(s_u, s_v);
    ij_next = s_u <= s_v ? ivec2(ij.x + stp.x, ij.y) : ivec2(ij.x, ij.y + stp.y);
    gone = s_leave > s_out || any(lessThan(ij_next, ivec2(0))) || any(greaterThanEqual(ij_next, n));
    ij_next = clamp(ij_next, ivec2(0), n - 1);
    return s_leave;
}

bool cj_start_point(vec3 P, vec3 L, out int face, out vec2 ab) {
    face = -1;
    ab = vec2(0.0);
    if (any(isnan(P)) || any(isinf(P)) || any(isnan(L)) || any(isinf(L))) return false;  // finite_segments
    int u = int(cj_scene.cell_axis_u), v = int(cj_scene.cell_axis_v), w = int(cj_scene.cell_axis_w);
    int nu = int(cj_scene.cell_nu), nv = int(cj_scene.cell_nv), width = int(cj_scene.cell_width);
    vec3 d = L - P;
    // The slab (face_cells._slab): the grid's box padded by 1e-5 of its size and magnitude,
    // the surface's range along w padded by 1% of its height and 1e-5 of its magnitude.
    float z_lo = cj_scene.cell_w_lo, z_hi = cj_scene.cell_w_hi;
    float z_pad = 0.01 * (z_hi - z_lo) + 1e-5 * (1.0 + max(abs(z_lo), abs(z_hi)));
    float u0 = cj_cell_line(0, 0), u1 = cj_cell_line(0, nu), v0 = cj_cell_line(1, 0), v1 = cj_cell_line(1, nv);
    float uv_pad = 1e-5 * (max(u1 - u0, v1 - v0) + max(max(abs(u0), abs(u1)), max(abs(v0), abs(v1))));
    vec3 lo, hi;
    lo[u] = u0 - uv_pad; lo[v] = v0 - uv_pad; lo[w] = z_lo - z_pad;
    hi[u] = u1 + uv_pad; hi[v] = v1 + uv_pad; hi[w] = z_hi + z_pad;
    float s_in, s_out;
    cj_clip_to_box(P, d, lo, hi, 1.0 + 128.0 * CJ_EPS, s_in, s_out);  // widened: a crossing at L is kept
    if (s_in > s_out) return false;
    vec3 X = P + s_in * d;
    ivec2 ij = ivec2(cj_cell_of(0, X[u]), cj_cell_of(1, X[v]));
    ivec2 stp = ivec2(sign(d[u]), sign(d[v]));
    vec2 Puv = vec2(P[u], P[v]), duv = vec2(d[u], d[v]);
    float z_scale = max(abs(z_lo), abs(z_hi));
    float meet_pad = 256.0 * CJ_EPS * (max(max(abs(P.x), abs(P.y)), abs(P.z))
                                       + max(max(abs(d.x), abs(d.y)), abs(d.z)) + z_scale);
    // Skip ahead to the first cell whose faces' height range the segment meets inside it.
    float s_enter = s_in;
    for (;;) {
        ivec2 ij_next;
        bool gone;
        float s_leave = cj_next_cell(ij, stp, Puv, duv, s_out, ij_next, gone);
        float z0 = P[w] + s_enter * d[w], z1 = P[w] + min(s_leave, s_out) * d[w];
        int row = ij.y * nu + ij.x;
        bool meets = max(z0, z1) + meet_pad >= cj_cell_rows[row].z_lo && min(z0, z1) - meet_pad <= cj_cell_rows[row].z_hi;
        if (meets) break;
        if (gone) return false;
        ij = ij_next;
        s_enter = s_leave;
    }
    // Test the cells' rows in order; a continued list stays in its cell.
    float best = CJ_INF;
    int row = ij.y * nu + ij.x;
    for (;;) {
        for (int c = 0; c < width; ++c) {  // the lowest column wins a tie (argmin)
            int f = cj_cell_faces[row * width + c].face;
            if (f < 0) continue;
            vec3 V[3], N[3];
            cj_triangle(f, V, N);
            float s, s_tol, rank;
            vec2 ab_f;
            bool inside = cj_triangle_crossing(P, d, V, s, s_tol, rank, ab_f);
            if (inside && s >= -s_tol && s <= 1.0 + s_tol && rank < best) {
                best = rank;
                face = f;
                ab = ab_f;
            }
        }
        ivec2 ij_next;
        bool gone;
        float s_leave = cj_next_cell(ij, stp, Puv, duv, s_out, ij_next, gone);
        int cont = cj_cell_rows[row].more;
        if (cont >= 0) {
            row = cont;
            continue;
        }
        if (best <= s_leave || gone) break;
        ij = ij_next;
        row = ij.y * nu + ij.x;
    }
    return face >= 0;
}
