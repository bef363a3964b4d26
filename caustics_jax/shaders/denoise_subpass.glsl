// One pixel of a 1-D sub-pass of the adaptive cross-bilateral denoiser (seed 004 eq. 21-28,
// Alg. 4; kernels.bilateral.denoise_subpass) on a row of pixels: (rho, lambda, delta) =
// (15, 5, 15) if lum(C(x)) < 0.1 C_scene, (10, 1, 2) if < 0.5 C_scene, else (5, 1, 1), with
// C_scene = c lum(L_min) (eq. 25-28; lum: Rec. 709 weights); neighbours q = x + i,
// i = -rho, -rho + lambda, ..., rho, i != 0, inside the row, weighted by w = w_z w_pos
// (eq. 21-23); the centre enters with weight 1 (Alg. 4 lines 6, 17): out = (C(x) + sum w C(q))
// / (1 + sum w) (eq. 24).
float cj_luminance(vec3 rgb) { return rgb.r * 0.2126 + rgb.g * 0.7152 + rgb.b * 0.0722; }

void cj_run(inout Record r) {
    int n = r.depth.length();
    int x = r.x;
    float c_scene = r.c_scene_factor * r.lum_l_min;
    float lum_c = cj_luminance(r.C[x]);
    bool dark = lum_c < 0.1 * c_scene, dim = lum_c < 0.5 * c_scene;
    int rho = dark ? 15 : (dim ? 10 : 5);
    int lam = dark ? 5 : 1;
    float delta = dark ? 15.0 : (dim ? 2.0 : 1.0);
    vec3 sum = vec3(0.0);
    float weight = 0.0;
    for (int i = -15; i <= 15; ++i) {
        int q = x + i;
        if (i == 0 || abs(i) > rho || abs(i) % lam != 0 || q < 0 || q >= n) continue;
        float w = cj_bilateral_weight(r.depth[x], r.depth[q], r.pos[x], r.pos[q], delta, r.eps);
        sum += w * r.C[q];
        weight += w;
    }
    r.C_out = (r.C[x] + sum) / (1.0 + weight);
}
