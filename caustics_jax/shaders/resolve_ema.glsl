// Resolve and temporal EMA of a collection point (seed 000 eq. 1-2; kernels.collection):
// L_o = tau I / (pi r^2), 0 at r = 0 (a point that gathered nothing); L_new = alpha L_hat +
// (1 - alpha) L_o (the paper's alpha = 0.8).
void cj_run(inout Record r) {
    float area = CJ_PI * r.r * r.r;
    r.L_o = area != 0.0 ? r.tau * r.I / area : vec3(0.0);
    r.L_new = r.alpha * r.L_hat + (1.0 - r.alpha) * r.L_o;
}
