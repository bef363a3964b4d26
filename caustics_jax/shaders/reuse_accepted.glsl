// Reuse acceptance of a previous collection point (seed 000 eq. 4; kernels.collection.reuse_accepted):
// |p_prev - p| <= r (the current point's radius, compared squared), n_prev . n >= 0.9, same material.
void cj_run(inout Record r) {
    vec3 d = r.p_prev - r.p;
    bool close = dot(d, d) <= r.r * r.r;
    bool aligned = dot(r.n_prev, r.n) >= 0.9;
    r.accepted = (close && aligned && r.m_prev == r.m) ? 1u : 0u;
}
