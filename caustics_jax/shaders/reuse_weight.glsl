// Gaussian reuse weight w = exp(-|p - p_prev|^2 / (2 sigma^2)), sigma = 0.75 r (seed 000 eq. 3;
// kernels.collection.reuse_weight). r = 0: a delta, 1 at coincident points, else 0.
float cj_reuse_weight(vec3 p_prev, vec3 p, float r) {
    vec3 d = p_prev - p;
    float d2 = dot(d, d);
    float sigma = 0.75 * r;
    float two_sigma2 = 2.0 * sigma * sigma;
    if (two_sigma2 > 0.0) return exp(-d2 / two_sigma2);
    return d2 == 0.0 ? 1.0 : 0.0;
}

void cj_run(inout Record r) { r.w = cj_reuse_weight(r.p_prev, r.p, r.r); }
