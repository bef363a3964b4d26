// Photon-differential footprint scale sigma = sqrt(A'/A) s^c (seed 004 eq. 10-11, Alg. 2,
// refraction variant; math.md §7): the three surface points refract the light direction
// with their own normals, all rays advance by the same hit distance t' (Alg. 2 lines 3-5),
// A and A' are the surface and caustic triangle areas (Alg. 2 line 6). The caustic
// triangle is formed from its edges hit_i - hit_00 = (x_i - x00) + t' (w_i - w00), with
// w_i - w00 expanded in n_i - n00 (photon_differentials._scatter_pair): hits x + t' w in
// world coordinates would lose eps |x| / texel of the edges (docs/irradiance.md, "float32").
// sigma = 0 (invalid, as the kernel's valid = False) when A = 0; a normal or l_dir is not a
// unit vector (to 16 eps of float32: zero, not finite, or another length); light arrives
// from behind a normal (l.n >= 0); a ray is totally internally reflected; t' is not finite
// and > 0; eta is not finite and > 0; s < 1 or c is not a whole number >= 0; or A'/A or
// sigma overflow.

// Alg. 2 line 2, refraction variant: eta = n_water / n_air.
vec3 cj_photon_dir(vec3 l_dir, vec3 n, float eta) { return cj_refract(l_dir, n, 1.0 / eta); }

// photon_differentials._unit_directions: |v.v - 1| <= 16 eps32 (NaN and inf fail).
bool cj_unit(vec3 v) { return abs(dot(v, v) - 1.0) <= 16.0 * CJ_EPS; }

// dw = w1 - w0 of two rays along l_dir refracted at n0, n1 (w = normalize(r)), from
// dn = n1 - n0: with e = 1/eta, r = e l - (e c + s) n, s = sqrt(k), k = cj_refraction_k(c, e),
// r1 - r0 = -(e c1 + s1) dn - (e dc + ds) n0, ds = (k1 - k0) / (s0 + s1) = e^2 dc (c0 + c1) / (s0 + s1),
// w1 - w0 = dr / m1 - r0 (m1 - m0) / (m0 m1), m1 - m0 = dr.(r0 + r1) / (m0 + m1).
// False where either ray is totally internally reflected or does not arrive from the side
// its normal faces (photon_differentials._scatter_pair).
bool cj_photon_dir_difference(vec3 l_dir, vec3 n0, vec3 n1, float eta, out vec3 dw) {
    dw = vec3(0.0);
    vec3 r0 = cj_photon_dir(l_dir, n0, eta), r1 = cj_photon_dir(l_dir, n1, eta);
    float e = 1.0 / eta;
    vec3 dn = n1 - n0;
    float c0 = dot(n0, l_dir), c1 = dot(n1, l_dir), dc = dot(dn, l_dir);
    float k0 = cj_refraction_k(c0, e), k1 = cj_refraction_k(c1, e);
    float m0 = cj_norm(r0), m1 = cj_norm(r1);
    if (!(c0 < 0.0 && c1 < 0.0) || !(k0 >= 0.0 && k1 >= 0.0) || !(m0 > 0.0) || !(m1 > 0.0)) return false;
    float s0 = sqrt(k0), s1 = sqrt(k1);
    float ds = s0 + s1 > 0.0 ? e * e * dc * (c0 + c1) / (s0 + s1) : 0.0;
    vec3 dr = -(e * c1 + s1) * dn - (e * dc + ds) * n0;
    dw = dr / m1 - r0 * (dot(dr, r0 + r1) / (m0 + m1) / (m0 * m1));
    return true;
}

float cj_photon_compression(vec3 x00, vec3 x10, vec3 x01, vec3 n00, vec3 n10, vec3 n01, vec3 l_dir,
                            float eta, float t_hit, float s, float c) {
    vec3 dx10 = x10 - x00, dx01 = x01 - x00;
    float A = 0.5 * cj_norm(cross(dx10, dx01));
    vec3 dw10, dw01;
    if (!(cj_unit(n00) && cj_unit(n10) && cj_unit(n01) && cj_unit(l_dir))) return 0.0;
    if (!(A > 0.0 && cj_finite_positive(t_hit) && cj_finite_positive(eta))) return 0.0;
    if (!(s >= 1.0 && !isinf(s) && c >= 0.0 && !isinf(c) && floor(c) == c)) return 0.0;
    if (!cj_photon_dir_difference(l_dir, n00, n10, eta, dw10)) return 0.0;
    if (!cj_photon_dir_difference(l_dir, n00, n01, eta, dw01)) return 0.0;
    float A_prime = 0.5 * cj_norm(cross(dx10 + t_hit * dw10, dx01 + t_hit * dw01));
    float ratio = A_prime / A;
    if (isinf(ratio) || isnan(ratio)) return 0.0;
    float sigma = sqrt(ratio) * pow(s, c);
    return isinf(sigma) || isnan(sigma) ? 0.0 : sigma;
}

void cj_run(inout Record r) {
    r.sigma = cj_photon_compression(r.x00, r.x10, r.x01, r.n00, r.n10, r.n01, r.l_dir, r.eta, r.t_hit, r.s, r.c);
}
