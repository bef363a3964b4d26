// Photon-differential footprint scale sigma = sqrt(A'/A) s^c (seed 004 eq. 10-11, Alg. 2,
// refraction variant; MATH.md §7): the three surface points refract the light direction
// with their own normals, all rays advance by the same hit distance t' (Alg. 2 lines 3-5),
// A and A' are the surface and caustic triangle areas (Alg. 2 line 6). sigma = 0 when A = 0.
vec3 cj_photon_hit(vec3 x, vec3 n, vec3 l_dir, float eta, float t_hit) {
    return x + t_hit * cj_safe_normalize(cj_refract(l_dir, n, 1.0 / eta));  // eta = n_water / n_air
}

float cj_triangle_area(vec3 p0, vec3 p1, vec3 p2) { return 0.5 * cj_norm(cross(p1 - p0, p2 - p0)); }

float cj_photon_compression(vec3 x00, vec3 x10, vec3 x01, vec3 n00, vec3 n10, vec3 n01, vec3 l_dir,
                            float eta, float t_hit, float s, float c) {
    float A = cj_triangle_area(x00, x10, x01);
    float A_prime = cj_triangle_area(cj_photon_hit(x00, n00, l_dir, eta, t_hit),
                                     cj_photon_hit(x10, n10, l_dir, eta, t_hit),
                                     cj_photon_hit(x01, n01, l_dir, eta, t_hit));
    return (A > 0.0 ? sqrt(A_prime / A) : 0.0) * pow(s, c);
}

void cj_run(inout Record r) {
    r.sigma = cj_photon_compression(r.x00, r.x10, r.x01, r.n00, r.n10, r.n01, r.l_dir, r.eta, r.t_hit, r.s, r.c);
}
