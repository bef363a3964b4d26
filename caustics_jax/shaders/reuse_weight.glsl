// Gaussian reuse weight w = exp(-|p - p_prev|^2 / (2 sigma^2)), sigma = 0.75 r (seed 000 eq. 3;
// kernels.collection.reuse_weight). r = 0: a delta, 1 at coincident points, else 0.
// d and sigma are divided by their largest magnitude before squaring (d.d or sigma^2 alone
// under- or overflow: r = |d| = 1e20 gave inf/inf), and the weight is 0 where the exponent
// passes -log(FLT_MIN) = 87.34, where exp underflows anyway.
float cj_reuse_weight(vec3 p_prev, vec3 p, float r) {
    vec3 d = p_prev - p;
    float sigma = 0.75 * r;
    float m = max(abs(sigma), max(abs(d.x), max(abs(d.y), abs(d.z))));
    if (m > 0.0) {
        d /= m;
        sigma /= m;
    }
    float d2 = dot(d, d);
    float two_sigma2 = 2.0 * sigma * sigma;
    if (d2 > 87.33655 * two_sigma2) return 0.0;
    return two_sigma2 > 0.0 ? exp(-d2 / two_sigma2) : 1.0;
}

void cj_run(inout Record r) { r.w = cj_reuse_weight(r.p_prev, r.p, r.r); }
