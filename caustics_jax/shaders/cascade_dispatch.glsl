// Cascade dispatch: thread id -> (texel, level, valid) (seed 004 Alg. 1 with three lines
// fixed, kernels.cascades.cascade_dispatch): level 0 fills W x H row by row; each later level
// gets the ring W H - (W/s)(H/s) (eq. 4) as the bottom band (Region0 = W DeltaY threads),
// the side bands (2 DeltaX (H - 2 DeltaY) threads, up to Region1) and the top band, with
// DeltaX = W (s - 1) / (2 s) (eq. 6). Fixed: line 24 Region0 (not Region1), line 26 >=
// (not >), line 33 Region1 (not Region0). Texel and level are 0 past the last level.
void cj_cascade_dispatch(int tid, int W, int H, int s, int n_levels, out ivec2 texel, out int level, out bool valid) {
    int dx = W * (s - 1) / (2 * s), dy = H * (s - 1) / (2 * s);
    int ring = W * H - (W / s) * (H / s);
    int total = W * H + (n_levels - 1) * ring;
    valid = tid >= 0 && tid < total;
    texel = ivec2(0);
    level = 0;
    if (!valid) return;
    if (tid < W * H) {
        texel = ivec2(tid % W, tid / W);
        return;
    }
    int beyond = tid - W * H;
    level = 1 + beyond / ring;
    int local = beyond % ring;
    int region0 = W * dy;
    int region1 = region0 + 2 * dx * (H - 2 * dy);
    if (local < region0) {
        texel = ivec2(local % W, local / W);
    } else if (local < region1) {
        int side = local - region0;  // line 24 fixed: Region0
        int x = side % (2 * dx);
        texel = ivec2(x >= dx ? x + (W - 2 * dx) : x, dy + side / (2 * dx));  // line 26 fixed: >=
    } else {
        int top = local - region1;  // line 33 fixed: Region1
        texel = ivec2(top % W, (H - dy) + top / W);
    }
}

void cj_run(inout Record r) {
    ivec2 texel;
    int level;
    bool valid;
    cj_cascade_dispatch(r.tid, r.ccm0_x, r.ccm0_y, r.s, r.n_levels, texel, level, valid);
    r.texel[0] = texel.x;
    r.texel[1] = texel.y;
    r.level = level;
    r.valid = valid ? 1u : 0u;
}
