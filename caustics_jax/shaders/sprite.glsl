// Photon sprite of seed 004 (kernels.sprites): side q = sqrt(r.w/(ccm0.x - 1) r.h/(ccm0.y - 1))
// q0 sigma (eq. 16); stretch a = 1 / (max(-l.n', 0) + eps), eps = 1e-3 (eq. 19); basis lp_F =
// l projected on the tangent plane of n' (projected twice: near normal incidence the first
// projection's normal part is rounding noise), lp_R = n' x lp_F, a fixed tangent at normal
// incidence (Fig. 6); corners x' + q (lp.x a lp_F + lp.y lp_R) / 2 over the patch (-1, 1),
// (1, 1), (-1, -1), (1, -1) (eq. 17-18); intensity I = R / (a q^2), 0 for q = 0 (eq. 20).
const float CJ_FORESHORTENING_EPS = 1e-3;
const vec2 CJ_PATCH[4] = vec2[4](vec2(-1.0, 1.0), vec2(1.0, 1.0), vec2(-1.0, -1.0), vec2(1.0, -1.0));

void cj_sprite_basis(vec3 l_dir, vec3 n_hit, out vec3 lp_F, out vec3 lp_R) {
    vec3 n = cj_safe_normalize(n_hit);
    vec3 tangential = l_dir - dot(l_dir, n) * n;
    tangential = tangential - dot(tangential, n) * n;
    vec3 helper = abs(n.x) < 0.9 ? vec3(1.0, 0.0, 0.0) : vec3(0.0, 1.0, 0.0);
    vec3 fallback = helper - dot(helper, n) * n;
    float tiny = 16.0 * CJ_EPS;
    lp_F = cj_safe_normalize(dot(tangential, tangential) <= tiny * tiny ? fallback : tangential);
    lp_R = cross(n, lp_F);
}

void cj_run(inout Record r) {
    float spacing = sqrt(r.r_width / float(r.ccm0_x - 1) * r.r_height / float(r.ccm0_y - 1));
    r.q = spacing * r.q0 * r.sigma;
    r.a = 1.0 / (max(-dot(r.l_dir, r.n_hit), 0.0) + CJ_FORESHORTENING_EPS);
    cj_sprite_basis(r.l_dir, r.n_hit, r.lp_F, r.lp_R);
    for (int i = 0; i < 4; ++i)
        r.corners[i] = r.x_hit + r.q * (CJ_PATCH[i].x * r.lp_F * r.a + CJ_PATCH[i].y * r.lp_R) / 2.0;
    float area = r.a * r.q * r.q;
    r.I = area != 0.0 ? r.R / area : 0.0;
}
