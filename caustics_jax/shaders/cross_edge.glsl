// cross_edge: the edge crossing of a walk (mesh.cross_edge; seed 001 eq. 3's edge
// parametrisation, math.md §3), cj_cross_edge_row in common.glsl. Record i is face i.
void cj_run(inout Record r) {
    int k_next;
    float t_out;
    vec2 ab;
    r.next_face = cj_cross_edge_row(true, r.edge, r.t, r.neighbor, r.neighbor_edge, k_next, t_out, ab);
    r.next_edge = k_next;
    r.next_t = t_out;
    r.next_ab = ab;
}
