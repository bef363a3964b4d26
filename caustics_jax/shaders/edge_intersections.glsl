// Intersections of the conic with the three triangle edges (seed 001 eq. 22-24, corrected
// in MATH.md §3; conic.edge_intersections). Edge 0: b = 0, t = a; edge 1: (a, b) = (1 - t, t);
// edge 2: a = 0, t = b. Outputs edge-major: t[2 e + k], valid[2 e + k].

// Real roots of q2 t^2 + q1 t + q0, ascending, cancellation-free (conic.solve_quadratic,
// Numerical Recipes §5.6): coefficients scaled by a power of two, q = -(q1 + sign(q1)
// sqrt(disc)) / 2, roots q / q2 and q0 / q; linear, tangent and all-zero cases masked.
void cj_solve_quadratic(float q2, float q1, float q0, out vec2 roots, out bvec2 valid) {
    float scale = max(max(abs(q2), abs(q1)), abs(q0));
    bool nonzero = scale > 0.0;
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

void cj_edge_intersections(float coef[6], out float t[6], out uint valid[6]) {
    float A = coef[0], B = coef[1], C = coef[2], D = coef[3], E = coef[4], F = coef[5];
    vec3 quad[3];
    quad[0] = vec3(A, D, F);                                   // b = 0 (eq. 23 prints A a^2 + C a + F)
    quad[1] = vec3(A + B - C, C + E - 2.0 * A - D, A + D + F); // a = 1 - b (eq. 24)
    quad[2] = vec3(B, E, F);                                   // a = 0 (eq. 22 prints B b^2 + D b + F)
    const float tol = 64.0 * CJ_EPS;  // the Python kernel's float32 default (export.EDGE_TOL)
    for (int k = 0; k < 3; ++k) {
        vec2 roots;
        bvec2 ok;
        cj_solve_quadratic(quad[k].x, quad[k].y, quad[k].z, roots, ok);
        for (int j = 0; j < 2; ++j) {
            bool keep = ok[j] && roots[j] >= -tol && roots[j] <= 1.0 + tol;
            t[2 * k + j] = keep ? clamp(roots[j], 0.0, 1.0) : 0.0;
            valid[2 * k + j] = keep ? 1u : 0u;
        }
    }
}

void cj_run(inout Record r) { cj_edge_intersections(r.coef, r.t, r.valid); }
