// photon_cull: seed 003 Fig. 9 (kernels.culling.photon_cull): the photon's throughput after
// the water, beta = cj_throughput (common.glsl); discarded mid-trace where beta < mid
// (status 1), not stored where albedo beta < final (status 2), else stored (status 0) with
// its energy; a culled photon stores 0.
void cj_run(inout Record r) {
    r.beta = cj_throughput(r.cos_i, r.t, r.eta, r.sigma_t);
    bool past_mid = cj_energy_kept(r.beta, r.mid);
    bool past_final = cj_energy_kept(r.albedo * r.beta, r.final);
    r.status = past_mid ? (past_final ? 0u : 2u) : 1u;
    r.stored = (past_mid && past_final) ? r.beta : 0.0;
}
