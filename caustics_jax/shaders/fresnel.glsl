// fresnel: exact dielectric Fresnel reflectance (F of seed 001 eq. 25), cj_fresnel_reflectance
// in common.glsl.
void cj_run(inout Record r) { r.R = cj_fresnel_reflectance(r.cos_i, r.eta); }
