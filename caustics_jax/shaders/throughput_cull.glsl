// throughput_cull: seed 003 Fig. 14 (kernels.culling.throughput_cull): a receiver's refracted
// path, its throughput estimated at the start point M0 before the solve (beta_hat =
// cj_throughput with d = |P - M0|), is solved only where beta_hat >= min_throughput.
void cj_run(inout Record r) {
    r.beta_hat = cj_throughput(r.cos_i, r.d, r.eta, r.sigma_t);
    r.keep = cj_energy_kept(r.beta_hat, r.min_throughput) ? 1u : 0u;
}
