// One lane of a scene file: start point, the scene's solver (cj_scene.solver: 0 the walk,
// 1 the one-step Newton), then D (seed 001 eq. 26-33) and the irradiance
// (eq. 25 corrected, math.md §6) at the solver's point, as the testbed's solve and
// path_irradiance return them: point, face and barycentrics only where a start point
// exists (else 0, -1, 0), residual the signed sine ('plane') there, D, D_valid and E only
// where the lane is FOUND (else 0).
void cj_run(inout Lane r) {
    int face;
    vec2 ab0;
    bool found = cj_start_point(r.P, r.L, face, ab0);
    r.start_face = face;
    r.start_ab = ab0;
    r.start_found = found ? 1u : 0u;
    uint status = CJ_NO_CROSSING;  // what the solvers report for a lane without a start point
    int steps = 0, crossed = 0, end_face = -1;
    vec2 end_ab = vec2(0.0);
    if (found && cj_scene.solver == 1u) {
        float f_end;
        NewtonState s = cj_newton(r.P, r.L, face, ab0, r.eta, cj_scene.tol, int(cj_scene.max_steps),
                                  cj_scene.initial_step, f_end);
        status = s.status;
        steps = s.steps;
        crossed = s.crossed;
        end_face = s.face;
        end_ab = s.ab;
    } else if (found) {
        WalkState s = cj_walk(r.P, r.L, face, ab0, true, r.eta, cj_scene.tol, int(cj_scene.max_steps),
                              cj_scene.bracket == 0u, int(cj_scene.ellipse_samples));
        status = s.status;
        steps = s.steps;
        crossed = s.crossed;
        end_face = s.face;
        end_ab = s.best_ab;
    }
    r.status = status;
    r.iterations = uint(steps);
    r.crossed = uint(crossed);
    r.face = found ? end_face : -1;
    r.ab = found ? end_ab : vec2(0.0);
    vec3 V[3], N[3];
    cj_triangle(r.face, V, N);
    r.M = found ? cj_barycentric_point(V, r.ab) : vec3(0.0);
    float f = 0.0;
    uint st;
    if (found) cj_signed_sine(V, N, r.P, r.L, r.ab, r.eta, f, st);
    r.residual = f;
    float D = 0.0, E = 0.0;
    uint D_valid = 0u, E_valid;
    if (status == CJ_FOUND) {  // D as the testbed reports it (ray_differential_D), E from D / d_L^2
        cj_ray_differential_D(V, N, r.P, r.L, r.ab, r.eta, D, D_valid);
        E = cj_path_irradiance(V, N, r.P, r.L, r.ab, r.eta, r.intensity, r.receiver_normal, r.sigma_t, E_valid);
    }
    r.D = D;
    r.D_valid = D_valid;
    r.E = E;
}
