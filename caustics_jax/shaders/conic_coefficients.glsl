// Conic coefficients A..F of the coplanarity constraint (seed 001 eq. 10-12; MATH.md §2):
// K = N^T Q with columns of N: n1 - n0, n2 - n0, n0 (eq. 7) and of Q: PL x V0V1,
// PL x V0V2, PL x PV0 (eq. 10); A = K11, B = K22, C = K12 + K21, D = K13 + K31,
// E = K23 + K32, F = K33.
void cj_conic_coefficients(vec3 V[3], vec3 N[3], vec3 P, vec3 L, out float coef[6]) {
    vec3 PL = L - P;
    vec3 Ncol[3] = vec3[3](N[1] - N[0], N[2] - N[0], N[0]);
    vec3 Qcol[3] = vec3[3](cross(PL, V[1] - V[0]), cross(PL, V[2] - V[0]), cross(PL, V[0] - P));
    float K[3][3];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) K[i][j] = dot(Ncol[i], Qcol[j]);
    coef[0] = K[0][0];
    coef[1] = K[1][1];
    coef[2] = K[0][1] + K[1][0];
    coef[3] = K[0][2] + K[2][0];
    coef[4] = K[1][2] + K[2][1];
    coef[5] = K[2][2];
}

void cj_run(inout Record r) { cj_conic_coefficients(r.V, r.N, r.P, r.L, r.coef); }
