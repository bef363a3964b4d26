// Helpers shared by the kernel ports: GLSL 450 versions of caustics_jax/geometry.py,
// barycentric.py and objectives.path_vectors. Every function mirrors the Python kernel
// line by line, so a difference in a conformance run points at one line.

const float CJ_EPS = 1.1920929e-7;  // float32 machine epsilon, jnp.finfo(float32).eps

float cj_safe_sqrt(float x) { return x > 0.0 ? sqrt(x) : 0.0; }

// geometry.norm / safe_normalize: |v|, and v / |v| or the zero vector (never NaN).
float cj_norm(vec3 v) { return cj_safe_sqrt(dot(v, v)); }

vec3 cj_safe_normalize(vec3 v) {
    float len = cj_norm(v);
    return len > 0.0 ? v * (1.0 / len) : vec3(0.0);
}

// GLSL refract semantics (MATH.md §1; seed 002 eq. 3.1-3.2), with the Python kernel's
// cancellation-free k = (1 - eta)(1 + eta) + (eta cos)^2 instead of 1 - eta^2 (1 - cos^2).
// Total internal reflection (k < 0) returns the zero vector.
vec3 cj_refract(vec3 I, vec3 N, float eta) {
    float cos_i = dot(N, I);
    float k = (1.0 - eta) * (1.0 + eta) + (eta * cos_i) * (eta * cos_i);
    if (k < 0.0) return vec3(0.0);
    return eta * I - (eta * cos_i + cj_safe_sqrt(k)) * N;
}

// Seed 001 eq. 3 and eq. 6-8: M = V0 + a (V1 - V0) + b (V2 - V0), same for the
// unnormalised interpolated normal n~.
vec3 cj_barycentric_point(vec3 X[3], vec2 ab) {
    return X[0] + ab.x * (X[1] - X[0]) + ab.y * (X[2] - X[0]);
}

// objectives.path_vectors: M, n_s, w_P = (P - M)/|P - M|, w_L = (L - M)/|L - M| (MATH.md §1).
bool cj_path_vectors(vec3 V[3], vec3 N[3], vec3 P, vec3 L, vec2 ab,
                     out vec3 M, out vec3 n_s, out vec3 w_P, out vec3 w_L) {
    M = cj_barycentric_point(V, ab);
    vec3 n_tilde = cj_barycentric_point(N, ab);
    vec3 PM = P - M;
    vec3 LM = L - M;
    n_s = cj_safe_normalize(n_tilde);
    w_P = cj_safe_normalize(PM);
    w_L = cj_safe_normalize(LM);
    return cj_norm(n_tilde) == 0.0 || cj_norm(PM) == 0.0 || cj_norm(LM) == 0.0;  // degenerate
}

// objectives.orthonormal_frame: branchless basis (s, t) of Duff et al. 2017.
void cj_orthonormal_frame(vec3 n, out vec3 s, out vec3 t) {
    float sgn = n.z >= 0.0 ? 1.0 : -1.0;
    float a = -1.0 / (sgn + n.z);
    float b = n.x * n.y * a;
    s = vec3(1.0 + sgn * n.x * n.x * a, sgn * b, -sgn * n.x);
    t = vec3(b, sgn + n.y * n.y * a, -n.y);
}
