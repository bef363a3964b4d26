// Start point of the walk: the first crossing M0 of segment P -> L with the surface, the
// crossing nearest P (seed 001 §3.4.2: M0 satisfies the coplanarity constraint trivially).
// Two paths sharing one segment-triangle test (Moller-Trumbore, start_points.segment_triangle):
// - grid (cj_scene.has_grid): the 2D DDA over the heightfield's cells of the testbed's grid
//   path, clipped to the slab z_min - pad <= z <= z_max + pad and to the grid's xy extent;
// - general: every face is tested and the smallest segment parameter wins (ties: the lowest
//   face index). The testbed traverses a BVH instead; both return the first crossing, and a
//   segment through a shared edge or vertex may pick a different one of the faces that meet
//   there (the walk then starts from the same point in another face). O(F) per lane: a real
//   backend would traverse its own acceleration structure here.

// Crossing of the segment P + s d, s in [0, 1], with triangle V: (s, ab, hit). Hits within
// 16 eps outside an edge count (a segment through a shared edge is never lost between two
// faces); segments in the triangle's plane (det = 0) do not hit. ab is projected into the
// closed triangle, s clipped to [0, 1].
bool cj_segment_triangle(vec3 P, vec3 d, vec3 V[3], out float s, out vec2 ab) {
    vec3 e1 = V[1] - V[0], e2 = V[2] - V[0];
    vec3 pvec = cross(d, e2);
    float det = dot(e1, pvec);
    float scale = sqrt(dot(d, d) * dot(e1, e1) * dot(e2, e2));
    bool ok = abs(det) > 16.0 * CJ_EPS * scale;
    float inv = ok ? 1.0 / det : 0.0;
    vec3 tvec = P - V[0];
    vec3 qvec = cross(tvec, e1);
    float a = dot(tvec, pvec) * inv, b = dot(d, qvec) * inv;
    s = dot(e2, qvec) * inv;
    const float tol = 16.0 * CJ_EPS;
    bool hit = ok && a >= -tol && b >= -tol && a + b <= 1.0 + tol && s >= -tol && s <= 1.0 + tol;
    a = max(a, 0.0);
    b = max(b, 0.0);
    float total = a + b > 1.0 ? a + b : 1.0;
    ab = vec2(a / total, b / total);
    s = clamp(s, 0.0, 1.0);
    return hit;
}

// Segment parameters [s_in, s_out] of P + s d inside the box [lo, hi], within [0, s_max]
// (start_points._clip_to_box: slabs with 1/d, an axis with d = 0 is inside or outside whole).
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

// Grid path: cells (i, j) along the xy projection of the segment, two faces per cell
// (2 (j nx + i) and the next; mesh.GridInfo), at most nx + ny + 1 cells.
bool cj_start_point_grid(vec3 P, vec3 L, out int face, out vec2 ab) {
    vec3 d = L - P;
    float z_min = cj_scene.z_min, z_max = cj_scene.z_max;
    float pad = 0.01 * (z_max - z_min) + 1e-5 * (1.0 + max(abs(z_min), abs(z_max)));  // rounding never prunes
    vec3 box_lo = vec3(cj_scene.grid_x0, cj_scene.grid_y0, z_min - pad);
    vec3 box_hi = vec3(cj_scene.grid_x1, cj_scene.grid_y1, z_max + pad);
    float s_in, s_out;
    cj_clip_to_box(P, d, box_lo, box_hi, 1.0, s_in, s_out);
    face = -1;
    ab = vec2(0.0);
    if (!(s_in <= s_out)) return false;
    vec3 X = P + s_in * d;
    vec2 cell = vec2(cj_scene.grid_dx, cj_scene.grid_dy);
    vec2 origin = vec2(cj_scene.grid_x0, cj_scene.grid_y0);
    ivec2 n_cells = ivec2(cj_scene.grid_nx, cj_scene.grid_ny);
    ivec2 ij = clamp(ivec2(floor((X.xy - origin) / cell)), ivec2(0), n_cells - 1);
    ivec2 stp = ivec2(sign(d.xy));
    bvec2 moving = notEqual(stp, ivec2(0));
    vec2 d_safe = vec2(moving.x ? d.x : 1.0, moving.y ? d.y : 1.0);
    vec2 boundary = origin + vec2(ij + ivec2(greaterThan(stp, ivec2(0)))) * cell;
    vec2 s_next = vec2(moving.x ? (boundary.x - P.x) / d_safe.x : CJ_INF,
                       moving.y ? (boundary.y - P.y) / d_safe.y : CJ_INF);
    vec2 s_delta = vec2(moving.x ? cell.x / abs(d_safe.x) : CJ_INF, moving.y ? cell.y / abs(d_safe.y) : CJ_INF);
    int cells = n_cells.x + n_cells.y + 1;
    for (int k = 0; k < cells; ++k) {
        int f0 = 2 * (ij.y * n_cells.x + ij.x);
        float best = CJ_INF;
        for (int c = 0; c < 2; ++c) {  // lower face first: it wins a tie, as argmin does
            vec3 V[3], N[3];
            cj_triangle(f0 + c, V, N);
            float s;
            vec2 ab_c;
            if (cj_segment_triangle(P, d, V, s, ab_c) && s < best) {
                best = s;
                face = f0 + c;
                ab = ab_c;
            }
        }
        if (face >= 0) return true;
        int axis = s_next.y < s_next.x ? 1 : 0;  // the cell wall the segment leaves through
        float s_leave = min(s_next.x, s_next.y);
        ij[axis] += stp[axis];
        s_next[axis] += s_delta[axis];
        if (any(lessThan(ij, ivec2(0))) || any(greaterThanEqual(ij, n_cells)) || s_leave > s_out) return false;
    }
    return false;
}

// General path: the smallest segment parameter over every face.
bool cj_start_point_general(vec3 P, vec3 L, out int face, out vec2 ab) {
    vec3 d = L - P;
    float best = 1.0 + 16.0 * CJ_EPS;  // just past the segment's end (segment_triangle's tolerance)
    face = -1;
    ab = vec2(0.0);
    for (int f = 0; f < int(cj_scene.n_faces); ++f) {
        vec3 V[3], N[3];
        cj_triangle(f, V, N);
        float s;
        vec2 ab_f;
        if (cj_segment_triangle(P, d, V, s, ab_f) && s < best) {
            best = s;
            face = f;
            ab = ab_f;
        }
    }
    return face >= 0;
}

bool cj_start_point(vec3 P, vec3 L, out int face, out vec2 ab) {
    return cj_scene.has_grid != 0u ? cj_start_point_grid(P, L, face, ab) : cj_start_point_general(P, L, face, ab);
}
