// Conic tangent (-v, u) in barycentric space (seed 001 eq. 13-15 with the symmetric part
// S = (K + K^T)/2, MATH.md §2: the paper's K^T is the gradient only for symmetric K).
vec2 cj_conic_tangent(float coef[6], vec2 ab) {
    float A = coef[0], B = coef[1], C = coef[2], D = coef[3], E = coef[4];
    float u = A * ab.x + C / 2.0 * ab.y + D / 2.0;
    float v = C / 2.0 * ab.x + B * ab.y + E / 2.0;
    return vec2(-v, u);
}

void cj_run(inout Record r) { r.t = cj_conic_tangent(r.coef, r.ab); }
