"""GLSL conformance on a Vulkan device (lavapipe in CI): every kernel's port reproduces the
exported reference within the manifest tolerances, and a wrong line makes it fail.

Skips, saying what is missing, where glslangValidator, a C compiler, the Vulkan headers
and loader or a Vulkan device are absent (`.ci/run` installs them on Debian).
"""

import shutil

import pytest

from caustics_jax import export as ex
from caustics_jax.shaders import conformance as conf

# The line of edge_intersections.glsl for edge a = 0 and its misprint in seed 001 eq. 22.
CORRECT_EDGE_LINE = "quad[2] = vec3(B, E, F);"
MISPRINTED_EDGE_LINE = "quad[2] = vec3(B, D, F);"


@pytest.fixture(scope="module")
def device(tmp_path_factory):
    """`(data_dir, work_dir, host)`: exported data and a built host that found a Vulkan device."""
    work = tmp_path_factory.mktemp("vk")
    data = tmp_path_factory.mktemp("refdata")
    try:
        conf._which("glslangValidator")
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
    path = shaders / "edge_intersections.glsl"
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
])
def test_other_plausible_wrong_lines_fail_conformance(device, kernel, line, wrong):
    data, work, host = device
    source = conf.shader_source(kernel)
    assert source.count(line) == 1
    report = conf.run_kernel(data, kernel, work, host=host, source=source.replace(line, wrong))
    assert report["pass_rate"] < 1.0
