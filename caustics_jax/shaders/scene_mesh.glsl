// The surface of a scene file: triangle gather and edge crossing (SurfaceMesh.triangle and
// mesh.cross_edge). Buffers (declared by the harness from caustics_scene.h's layout):
// cj_scene (one record), cj_vertices[], cj_faces[].

// Vertex positions V and unit normals N of a face, rows V0, V1, V2. Negative (invalid) face
// indices gather face 0, as the testbed does, so masked lanes stay finite.
void cj_triangle(int face, out vec3 V[3], out vec3 N[3]) {
    Face f = cj_faces[max(face, 0)];
    for (int i = 0; i < 3; ++i) {
        V[i] = cj_vertices[f.v[i]].position;
        N[i] = cj_vertices[f.v[i]].normal;
    }
}

// Cross edge `edge` of `face` at edge parameter t into the neighbour across it (mesh.cross_edge,
// cj_cross_edge_row in common.glsl with this face's adjacency row).
int cj_cross_edge(int face, int edge, float t, out int k_next, out float t_out, out vec2 ab) {
    Face f = cj_faces[max(face, 0)];
    return cj_cross_edge_row(face >= 0, edge, t, f.neighbor, f.neighbor_edge, k_next, t_out, ab);
}
