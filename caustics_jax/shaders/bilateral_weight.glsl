// bilateral_weight: seed 004 eq. 21-23, cj_bilateral_weight in common.glsl.
void cj_run(inout Record r) { r.w = cj_bilateral_weight(r.z_p, r.z_q, r.pos_p, r.pos_q, r.delta, r.eps); }
