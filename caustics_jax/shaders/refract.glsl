// refract: GLSL refract semantics (math.md §1; seed 002 eq. 3.1-3.2), cj_refract in common.glsl.
void cj_run(inout Record r) { r.T = cj_refract(r.I, r.N, r.eta); }
