// Photon ray intensity of seed 004 (kernels.attenuation): R = L I_att F (eq. 12) with the
// underwater attenuation tent I_att (eq. 13): x = 1 - clamp(t, 0, t_max) / t_max,
// 1 - (x - gamma)/(1 - gamma) if x > gamma else 1 - (gamma - x)/gamma; and the Schlick-like
// Fresnel term F_refl = F_frac + (1 - F_frac)(1 - cos)^F_exp, cos = clamp(-l.n, 0, 1) (eq. 14),
// F_refr = 1 - F_refl (eq. 15), the F of a refracted photon; 0^F_exp is its limit (1 for F_exp = 0).
float cj_intensity_attenuation(float t, float t_max, float gamma) {
    // as the kernel inside jit: t_max floored at the smallest normal float32, gamma clipped
    // into (0, 1), so a zero or out-of-range parameter gives a finite tent
    t_max = max(t_max, CJ_TINY);
    gamma = clamp(gamma, CJ_TINY, 0.99999994);  // nextafter(1, 0) in float32
    float x = 1.0 - clamp(t, 0.0, t_max) / t_max;
    return x > gamma ? 1.0 - (x - gamma) / (1.0 - gamma) : 1.0 - (gamma - x) / gamma;
}

float cj_fresnel_reflect_approx(vec3 l_dir, vec3 n, float f_frac, float f_exp) {
    float cos_raw = -dot(l_dir, n);
    float c = clamp(cos_raw, 0.0, 1.0);
    // pow(0, y) is undefined in GLSL for y <= 0: at normal incidence take the limit; a NaN
    // direction is no lit lane either (the kernel's base > 0 is False for NaN)
    float base = 1.0 - c;
    bool lit = base > 0.0 && !isnan(cos_raw);
    float power = lit ? pow(base, f_exp) : (f_exp == 0.0 ? 1.0 : 0.0);
    return f_frac + (1.0 - f_frac) * power;
}

void cj_run(inout Record r) {
    r.i_att = cj_intensity_attenuation(r.t, r.t_max, r.gamma);
    r.F_refl = cj_fresnel_reflect_approx(r.l_dir, r.n, r.f_frac, r.f_exp);
    r.F_refr = 1.0 - r.F_refl;
    r.R = r.L * r.i_att * r.F_refr;
}
