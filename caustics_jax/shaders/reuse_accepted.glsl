// Reuse acceptance of a previous collection point (seed 000 eq. 4; kernels.collection.reuse_accepted):
// |p_prev - p| <= r (the current point's radius, compared squared after dividing both by their
// largest magnitude, so the squares cannot under- or overflow), n_prev . n >= 0.9, same material.
void cj_run(inout Record r) {
    vec3 d = r.p_prev - r.p;
    float radius = r.r;
    float m = max(abs(radius), max(abs(d.x), max(abs(d.y), abs(d.z))));
    if (m > 0.0) {
        d /= m;
        radius /= m;
    }
    bool close = dot(d, d) <= radius * radius;
    bool aligned = dot(r.n_prev, r.n) >= 0.9;
    r.accepted = (close && aligned && r.m_prev == r.m) ? 1u : 0u;
}
