// Exact unpolarised dielectric Fresnel reflectance, the F of seed 001 eq. 25
// (geometry.fresnel_reflectance): R = (r_s^2 + r_p^2) / 2, R = 1 under TIR and at grazing.
float cj_fresnel_reflectance(float cos_i, float eta) {
    cos_i = clamp(abs(cos_i), 0.0, 1.0);
    float cos_t2 = (1.0 - eta) * (1.0 + eta) + (eta * cos_i) * (eta * cos_i);  // 1 - sin_t^2
    float cos_t = cj_safe_sqrt(cos_t2);
    float den_s = eta * cos_i + cos_t;
    float den_p = cos_i + eta * cos_t;
    if (!(cos_t2 > 0.0 && den_s > 0.0 && den_p > 0.0)) return 1.0;
    float r_s = (eta * cos_i - cos_t) / den_s;
    float r_p = (cos_i - eta * cos_t) / den_p;
    return (r_s * r_s + r_p * r_p) / 2.0;
}

void cj_run(inout Record r) { r.R = cj_fresnel_reflectance(r.cos_i, r.eta); }
