// Cross-bilateral weight w = w_z w_pos (seed 004 eq. 21-23; kernels.bilateral.bilateral_weight):
// w_z = 1 / (|z_p - z_q| + eps) (eq. 22; Alg. 4 line 22 uses eps = 1),
// w_pos = 1 / (1 + 10 d.d / delta^2), d = pos_p - pos_q (eq. 23).
float cj_bilateral_weight(float z_p, float z_q, vec3 pos_p, vec3 pos_q, float delta, float eps) {
    vec3 d = pos_p - pos_q;
    float w_z = 1.0 / (abs(z_p - z_q) + eps);
    float w_pos = 1.0 / (1.0 + 10.0 * dot(d, d) / (delta * delta));
    return w_z * w_pos;
}

void cj_run(inout Record r) { r.w = cj_bilateral_weight(r.z_p, r.z_q, r.pos_p, r.pos_q, r.delta, r.eps); }
