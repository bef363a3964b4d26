"""GLSL conformance on a Vulkan device (lavapipe in CI): every kernel's port reproduces the
exported reference within the manifest tolerances, the start point (face cells), the walk
and the one-step Newton, D and irradiance pass on every exported scene, and a wrong line
makes either fail.

Skips, saying what is missing, where glslangValidator, a C compiler, the Vulkan headers
and loader or a Vulkan device are absent (`.ci/run` installs them on Debian).
"""

import json
import shutil

import numpy as np
import pytest

from caustics_jax import export as ex
from caustics_jax.shaders import conformance as conf
from caustics_jax.shaders import scene_conformance as sc
from caustics_jax.shaders import vulkan as vk

#: Lanes per exported scene in the tests (`make conformance` exports 4096).
SCENE_LANES = 256

# The line of edge_intersections.glsl for edge a = 0 and its misprint in seed 001 eq. 22.
CORRECT_EDGE_LINE = "return vec3(B, E, F);"
MISPRINTED_EDGE_LINE = "return vec3(B, D, F);"


@pytest.fixture(scope="module")
def device(tmp_path_factory):
    """`(data_dir, work_dir, host)`: exported data and a built host that found a Vulkan device."""
    work = tmp_path_factory.mktemp("vk")
    data = tmp_path_factory.mktemp("refdata")
    try:
        vk.which("glslangValidator")
        host = conf.build_host(work)
        ex.export(data, kernels=["fresnel"], count=8, seed=1)
        conf.run_kernel(data, "fresnel", work, host=host)  # probes the device
    except conf.Unavailable as exc:
        pytest.skip(f"no Vulkan conformance run possible here: {exc}")
    ex.export(data, count=64, seed=11)
    return data, work, host


@pytest.mark.parametrize("kernel", list(ex.KERNELS))
def test_glsl_port_conforms_on_the_vulkan_device(device, kernel):
    data, work, host = device
    report = conf.run_kernel(data, kernel, work, host=host)
    assert report["device"]
    failing = {name: f for name, f in report["fields"].items() if f["pass_rate"] < 1}
    assert report["pass_rate"] == 1.0, f"{kernel} on {report['device']}: {failing}, records {report['failures'][:10]}"


def test_misprinted_edge_quadratic_fails_conformance(device, tmp_path):
    """Seed 001 eq. 22 as printed (`B b^2 + D b + F` for the edge a = 0) must be caught."""
    data, work, host = device
    shaders = tmp_path / "shaders"
    shutil.copytree(conf.SHADER_DIR, shaders, ignore=shutil.ignore_patterns("*.py", "__pycache__"))
    path = shaders / "common.glsl"  # cj_edge_quadratic, shared by the kernel and the walk
    text = path.read_text()
    assert text.count(CORRECT_EDGE_LINE) == 1
    path.write_text(text.replace(CORRECT_EDGE_LINE, MISPRINTED_EDGE_LINE))
    report = conf.run_kernel(data, "edge_intersections", work, host=host,
                             source=conf.shader_source("edge_intersections", shaders))
    assert report["pass_rate"] < 0.9
    assert report["fields"]["valid"]["mismatches"] > 0 or report["fields"]["t"]["pass_rate"] < 1


def test_a_shader_that_skips_an_output_cannot_pass(device):
    """Outputs are hidden (NaN) before upload: echoing the input record does not pass."""
    data, work, host = device
    source = conf.shader_source("d_factor").replace("void main() {", "void main_unused() {")
    source += "void main() { uint i = gl_GlobalInvocationID.x; if (i < push.count) records_out[i] = records_in[i]; }\n"
    report = conf.run_kernel(data, "d_factor", work, host=host, source=source)
    assert report["pass_rate"] == 0.0


def test_conformance_table_lists_every_output(device, tmp_path):
    data, work, host = device
    reports = [conf.run_kernel(data, k, work, host=host) for k in ("refract", "fixed_point")]
    table = conf.format_table(reports)
    assert "| refract | T |" in table and "| fixed_point | code (exact) |" in table


@pytest.mark.parametrize("kernel, line, wrong", [
    ("d_factor", "vec3 w_L_d = -eta * W[j]", "vec3 w_L_d = eta * W[j]"),  # eq. 31 as extracted
    ("edge_intersections", "const float tol = 64.0 * CJ_EPS;", "const float tol = 0.0;"),  # no root window
    ("photon_compression", "cj_refract(l_dir, n, 1.0 / eta)", "cj_refract(l_dir, n, eta)"),  # inverted ratio
    ("fixed_point", "uint(roundEven(max(x, 0.0) * 268435456.0))", "uint(max(x, 0.0) * 268435456.0)"),  # truncation
    ("photon_cull", "cj_energy_kept(r.albedo * r.beta, r.final)", "cj_energy_kept(r.beta, r.final)"),  # no albedo
    ("throughput_cull", "cj_throughput(r.cos_i, r.d, r.eta, r.sigma_t)",
     "cj_throughput(r.cos_i, 0.0, r.eta, r.sigma_t)"),  # no attenuation
])
def test_other_plausible_wrong_lines_fail_conformance(device, kernel, line, wrong):
    data, work, host = device
    source = conf.shader_source(kernel)
    assert source.count(line) == 1
    report = conf.run_kernel(data, kernel, work, host=host, source=source.replace(line, wrong))
    assert report["pass_rate"] < 1.0


@pytest.fixture(scope="module")
def scenes(device, tmp_path_factory):
    """`(data_dir, work_dir, host, spv)`: every scene exported for both solvers, the scene
    shader compiled once."""
    _, work, host = device
    data = tmp_path_factory.mktemp("scenes")
    ex.export(data, kernels=[], scenes=list(ex.SCENES), lanes=SCENE_LANES, seed=5)
    spv = conf.compile_shader(sc.scene_shader_source(), work / "scene.spv")
    return data, work, host, spv


@pytest.mark.parametrize("solver", ["walk", "newton"])
@pytest.mark.parametrize("scene", list(ex.SCENES))
def test_glsl_solvers_conform_on_every_scene(scenes, scene, solver):
    """Start point, walk or Newton, D and irradiance: stable-lane status agreement >= 99.9%,
    points within M_tol where both are FOUND, no FOUND point off by more than tol (float64
    check), D and E at the port's own points within their tolerances; the start points,
    through the same face cells as the testbed's, agree on every lane."""
    data, work, host, spv = scenes
    r = sc.run_scene(data, ex.scene_stem(scene, solver), work, host=host, spv=spv)
    assert r["lanes"] == SCENE_LANES and r["device"] and r["solver"] == solver
    assert r["start_found_agreement"] == 1.0, r["start_found_agreement"]
    if not scene.startswith("stress_"):  # (the stress scenes sit within float32's rounding by design)
        assert r["conditioned_lanes"] >= 0.95 * SCENE_LANES, r["conditioned_lanes"]
    assert r["silent_wrong"] == 0, f"{scene}: lanes {r['silent_lanes']} FOUND with an angle error above tol"
    assert r["M_outside_tol"] == 0, f"{scene}: lanes {r['M_outside_lanes']} FOUND at another point"
    assert r["D"]["violations"] == 0 and r["E"]["violations"] == 0, (r["D"], r["E"])
    assert r["status_agreement"] >= 0.999, (scene, r["disagreements"], r["disagreeing_lanes"])
    assert r["passed"]
    if scene != "stress_p_near_surface":  # P within a micrometre of the surface: nothing is found
        assert r["found_port"] > 0


@pytest.mark.parametrize("file, line, wrong", [
    # an edge index: the neighbour across the next edge
    ("common.glsl", "int g = valid_face ? neighbor[k] : -1;", "int g = valid_face ? neighbor[(k + 1) % 3] : -1;"),
    # the shared edge runs the other way in the neighbour: forgetting it
    ("common.glsl", "cj_edge_param_from_vertex_order(max(k_next, 0), 1.0 - s);",
     "cj_edge_param_from_vertex_order(max(k_next, 0), s);"),
    # a sign: the f carried to the next face's entry negated (every bracket test there
    # reads it). The tangent oriented outward at an entry point, the sign this case had
    # flipped, is seen by no lane of these scenes since a chord cut no longer stalls in phi
    # (walk_steps._bisect_update): the exit is the arc's one other edge root either way, and the
    # chord cuts do not read the pencil frame; neither is a second direction along +t0.
    ("walk.glsl", "s.f_exit = fx;", "s.f_exit = -fx;"),
    # the bracket end the cut replaces
    ("walk.glsl", "bool to_hi = cj_opposite(fm, s.f_lo);", "bool to_hi = cj_opposite(fm, s.f_hi);"),
    # the DDA's next cell wall on the wrong side of the cell
    ("start_point.glsl", "float x = cj_cell_line(k, clamp(i + (stp[k] > 0 ? 1 : 0), 0, n));",
     "float x = cj_cell_line(k, clamp(i + (stp[k] > 0 ? 0 : 1), 0, n));"),
    # the Fresnel transmittance seen from the water side
    ("common.glsl", "cj_fresnel_reflectance(dot(w_L, n_s), 1.0 / eta)", "cj_fresnel_reflectance(dot(w_L, n_s), eta)"),
])
def test_a_broken_line_of_the_glsl_walk_fails_conformance(scenes, tmp_path, file, line, wrong):
    data, work, host, _ = scenes
    shaders = tmp_path / "shaders"
    shutil.copytree(conf.SHADER_DIR, shaders, ignore=shutil.ignore_patterns("*.py", "__pycache__"))
    path = shaders / file
    text = path.read_text()
    assert text.count(line) == 1, line
    path.write_text(text.replace(line, wrong))
    spv = conf.compile_shader(sc.scene_shader_source(shaders), tmp_path / "broken.spv")
    reports = [sc.run_scene(data, s, tmp_path / s, host=host, spv=spv) for s in ("wavy_steep", "lagoon")]
    assert not all(r["passed"] for r in reports), [(r["scene"], r["status_agreement"]) for r in reports]


def test_the_glsl_newton_with_cycles_mnee_step_control_conforms(scenes, tmp_path):
    """`initial_step=0.1` (Cycles' MNEE step control, `newton-hv-step-gentle`), exported with
    `--newton-initial-step 0.1`: the shader reads it from the scene record and agrees; the
    gentle first step costs iterations on the pool against the full step."""
    from caustics_jax import Newton

    data, work, host, spv = scenes
    out = tmp_path / "mnee"
    ex.export(out, kernels=[], scenes=["wavy_steep"], lanes=SCENE_LANES, seed=5, solvers=["newton"],
              newton=Newton(stepping="one_step", constraint="half_vector", initial_step=0.1))
    m, b = ex.load_scene(out, "wavy_steep.newton")
    assert m["options"]["initial_step"] == 0.1 and abs(b["scene"]["initial_step"][0] - 0.1) < 1e-7
    r = sc.run_scene(out, "wavy_steep.newton", work / "mnee", host=host, spv=spv)
    assert r["passed"] and r["status_agreement"] >= 0.999, (r["disagreements"], r["D"], r["E"])
    full = sc.run_scene(data, "wavy_steep.newton", work, host=host, spv=spv)
    assert r["iterations_port"] > full["iterations_port"]


@pytest.mark.parametrize("line, wrong", [
    # the half vector's derivative with the wrong sign: steps go uphill
    ("vec3 dh = -(dg - dot(h, dg) * h) * inv_g;", "vec3 dh = (dg - dot(h, dg) * h) * inv_g;"),
    # Cramer's rule with the Jacobian transposed
    ("vec2(c1.y * r.x - c1.x * r.y, c0.x * r.y - c0.y * r.x)",
     "vec2(c1.y * r.x - c0.y * r.y, c0.x * r.y - c1.x * r.x)"),
    # the re-projection's ray aimed from the tentative point instead of P
    ("float s = ok ? dot(n, V[0] - P) / denom : 0.0;", "float s = ok ? dot(n, V[0] - T) / denom : 0.0;"),
])
def test_a_broken_line_of_the_glsl_newton_fails_conformance(scenes, tmp_path, line, wrong):
    data, work, host, _ = scenes
    shaders = tmp_path / "shaders"
    shutil.copytree(conf.SHADER_DIR, shaders, ignore=shutil.ignore_patterns("*.py", "__pycache__"))
    path = shaders / "newton.glsl"
    text = path.read_text()
    assert text.count(line) == 1, line
    path.write_text(text.replace(line, wrong))
    spv = conf.compile_shader(sc.scene_shader_source(shaders), tmp_path / "broken.spv")
    reports = [sc.run_scene(data, ex.scene_stem(s, "newton"), tmp_path / s, host=host, spv=spv)
               for s in ("wavy_steep", "lagoon")]
    assert not all(r["passed"] for r in reports), [(r["scene"], r["status_agreement"]) for r in reports]


def test_a_scene_shader_that_echoes_its_input_cannot_pass(scenes):
    """Outputs and the reference are hidden before upload: copying the lane does not pass."""
    data, work, host, _ = scenes
    source = sc.scene_shader_source().replace("void main() {", "void main_unused() {")
    source += "void main() { uint i = gl_GlobalInvocationID.x; if (i < push.count) lanes_out[i] = lanes_in[i]; }\n"
    r = sc.run_scene(data, "wavy_gentle", work, host=host, source=source)
    assert not r["passed"] and r["status_agreement"] == 0.0


def test_scene_table_lists_every_scene(scenes):
    data, work, host, spv = scenes
    reports = [sc.run_scene(data, s, work, host=host, spv=spv) for s in ("flat_pool", "no_crossing")]
    table = sc.format_scene_table(reports)
    assert "| flat_pool |" in table and "| no_crossing |" in table


# Non-finite inputs (a record cannot carry them in an export: a NaN reference has no
# tolerance); the kernel's jitted reference is finite for each, and the port must match it.
NAN, INF = float("nan"), float("inf")
NON_FINITE = {
    "refract": [("I", 0, NAN), ("N", 1, NAN), ("eta", None, NAN), ("eta", None, INF)],  # cj_refract: NaN k -> 0
    "fresnel": [("cos_i", None, NAN)],  # clamp(NaN) is undefined in GLSL; the kernel gives R = 1
    "edge_intersections": [("coef", 0, INF), ("coef", 0, -INF), ("coef", 4, NAN)],  # no roots
    "signed_sine": [("P", 0, INF), ("L", 2, -INF)],  # cj_path_vectors: an infinite length is degenerate
    "photon_cull": [("cos_i", None, NAN), ("t", None, INF)],  # T = 0 (R = 1); attenuated to 0, none in clear water
}


@pytest.mark.parametrize("kernel", list(NON_FINITE))
def test_a_port_masks_non_finite_inputs_as_its_kernel(device, tmp_path, kernel):
    """The hostile-input probe of 2026-11-30 found these ports answering NaN, a root, status
    OK or R = 0.047 where the kernel masks the lane; the records reuse a clean export's
    tolerances, with inputs made non-finite and the reference recomputed (jitted, float64,
    as `export_kernel` computes it)."""
    import jax

    import caustics_jax as cj
    from caustics_jax.export.records import pack_records

    _, work, host = device
    spec = ex.KERNELS[kernel]
    manifest, raw = ex.export_kernel(spec, 8, 3)
    clean = ex.read_records(manifest, raw)
    rows = {k: [] for k in clean}
    for field, index, value in NON_FINITE[kernel]:
        for r in range(4):  # four ordinary records, each with one input made non-finite
            for k, v in clean.items():
                rows[k].append(v[r].copy())
            x = rows[field][-1]
            if index is None:
                rows[field][-1] = np.asarray(value, x.dtype)
            else:
                x.reshape(-1)[index] = value
    values = {k: np.stack(v) for k, v in rows.items()}
    with cj.precision("float64"):
        args = {f.name: jax.numpy.asarray(values[f.name], jax.numpy.float64) for f in spec.inputs()}
        ref = {k: np.asarray(v) for k, v in jax.jit(spec.evaluate)(args).items()}
    for name, v in ref.items():
        assert np.all(np.isfinite(v)), (kernel, name, v)  # the kernel masks these lanes
        values[name] = v
    count = len(values["case_tag"])
    hostile = {**manifest, "count": count}
    (tmp_path / f"{kernel}.json").write_text(json.dumps(hostile))
    (tmp_path / f"{kernel}.bin").write_bytes(pack_records(spec, values))
    report = conf.run_kernel(tmp_path, kernel, work, host=host)
    assert report["pass_rate"] == 1.0, (kernel, report["fields"], report["failures"][:10])


def test_the_gpu_recipe_lists_the_devices_and_skips_without_a_gpu(device, tmp_path, capsys):
    """`tools/gpu_recipe.py`: the devices listed with type, driver and subgroup size; a CPU
    driver (lavapipe) is never picked by default, a name that matches nothing skips cleanly,
    and a GPU would be picked before a CPU driver."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "tools" / "gpu_recipe.py"
    spec = importlib.util.spec_from_file_location("gpu_recipe", path)
    recipe = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(recipe)
    _, work, host = device
    devices = vk.list_devices(host)
    assert devices and all(d["name"] and d["type"] in ("integrated", "discrete", "virtual", "cpu", "other")
                           for d in devices)
    gpu = {"index": 9, "type": "discrete", "name": "Some GPU"}
    assert recipe.pick([{"index": 0, "type": "cpu", "name": "llvmpipe"}, gpu], None) is gpu
    assert recipe.pick([{"index": 0, "type": "cpu", "name": "llvmpipe"}], None) is None
    assert recipe.main(["--out", str(tmp_path), "--device", "no such device"]) == 0
    assert "skipped, no device named like 'no such device'" in capsys.readouterr().out
    listed = json.loads((tmp_path / "devices.json").read_text())
    assert listed["chosen"] is None and listed["devices"] == devices
    if all(d["type"] == "cpu" for d in devices):
        assert recipe.main(["--out", str(tmp_path)]) == 0
        assert "skipped, no GPU" in capsys.readouterr().out
