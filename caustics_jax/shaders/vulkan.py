"""The Vulkan toolchain of the conformance harness: the GLSL struct of a std430 record, the
shader compiler (glslangValidator), the C host (`host.c`, built with `cc -lvulkan`) and
running it (docs/export.md "The GLSL ports and the conformance harness").

`Unavailable` says what is missing (no compiler, no Vulkan headers or loader, no device),
so that the tests skip with the reason.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
from pathlib import Path

SHADER_DIR = Path(__file__).resolve().parent
LOCAL_SIZE = 64  # host.c dispatches ceil(count / 64) workgroups


class Unavailable(RuntimeError):
    """The toolchain or the Vulkan device needed for a conformance run is missing."""


def glsl_struct(kernel, name: str = "Record") -> str:
    """GLSL `struct <name>` matching the std430 layout of `export.layout` (vec3 + explicit pad)
    of a `Kernel` (or anything with `.fields`, or a list of `Field`)."""
    lines = [f"struct {name} {{"]
    for f in getattr(kernel, "fields", kernel):
        lines.append(f"    {f.glsl} {f.name}{f'[{f.length}]' if f.length else ''};")
        if f.glsl == "vec3" and not f.length:
            lines.append(f"    float _pad_{f.name};  // vec3 padded to 16 bytes")
    lines.append("};")
    return "\n".join(lines)


def which(tool: str) -> str:
    """The path of `tool`, or Unavailable."""
    path = shutil.which(tool)
    if path is None:
        raise Unavailable(f"{tool} not found on PATH")
    return path


def build_host(cache_dir: Path) -> Path:
    """Compile host.c (once per source version) into `cache_dir`; Unavailable if it cannot."""
    src = SHADER_DIR / "host.c"
    digest = hashlib.sha256(src.read_bytes()).hexdigest()[:12]
    exe = Path(cache_dir) / f"cj_vk_host_{digest}"
    if exe.exists():
        return exe
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise Unavailable("no C compiler (cc) to build the Vulkan host")
    Path(cache_dir).mkdir(parents=True, exist_ok=True)
    tmp = exe.with_suffix(".tmp")
    proc = subprocess.run([cc, "-O2", "-std=c11", "-o", str(tmp), str(src), "-lvulkan"],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        hint = " (install libvulkan-dev)" if "vulkan" in proc.stderr else ""
        raise Unavailable(f"cannot build the Vulkan host{hint}: {proc.stderr.strip()[:400]}")
    tmp.replace(exe)
    return exe


def compile_shader(source: str, out: Path) -> Path:
    """glslangValidator -V (Vulkan 1.0 SPIR-V); raises RuntimeError with its log on errors."""
    glslang = which("glslangValidator")
    comp = out.with_suffix(".comp")
    comp.write_text(source)
    proc = subprocess.run([glslang, "-V", "--target-env", "vulkan1.0", "-o", str(out), str(comp)],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"glslangValidator failed on {comp}:\n{proc.stdout}{proc.stderr}")
    return out


def host_output(stdout: str) -> tuple[str, dict]:
    """Device name and the timing of the host's stdout: `{"wall": s, "cpu": s}` of the fastest
    dispatch (wall time of submit to fence; the host process's CPU time over it, all threads,
    which is the shader's own CPU time on a CPU driver such as lavapipe)."""
    lines = stdout.strip().splitlines()
    timing = {"wall": None, "cpu": None, "device_type": None, "driver_version": None}
    for line in lines[1:]:
        key, *values = line.split()
        if key in ("dispatch_seconds", "dispatch_cpu_seconds") and values:
            timing["wall" if key == "dispatch_seconds" else "cpu"] = float(values[0])
        elif key in ("device_type", "driver_version") and values:
            timing[key] = values[0]
    return (lines[0] if lines else ""), timing


def list_devices(host: Path) -> list[dict]:
    """The Vulkan devices the host sees (`cj_vk_host --list`): per device `index`, `type`
    ("discrete", "integrated", "virtual", "cpu", "other"), `vendor_id`, `device_id`,
    `driver_version`, `api_version`, `subgroup_size` (0: unknown) and `name`. Unavailable
    when there is no Vulkan instance or device."""
    proc = subprocess.run([str(host), "--list"], capture_output=True, text=True)
    if proc.returncode == 3:
        raise Unavailable(f"no Vulkan device: {proc.stderr.strip()}")
    if proc.returncode != 0:
        raise RuntimeError(f"Vulkan host --list failed ({proc.returncode}): {proc.stderr.strip()}")
    keys = ("index", "type", "vendor_id", "device_id", "driver_version", "api_version", "subgroup_size", "name")
    devices = []
    for line in proc.stdout.strip().splitlines():
        d = dict(zip(keys, line.split("\t", len(keys) - 1), strict=True))
        d["index"], d["subgroup_size"] = int(d["index"]), int(d["subgroup_size"])
        devices.append(d)
    return devices


def run_host(host: Path, spv: Path, records_in: Path, records_out: Path, count: int, stride: int,
             extra=(), repeat: int = 1) -> tuple[str, dict]:
    """Run `spv` over `count` records of `stride` bytes (binding 0 in, 1 out; `extra` files
    at bindings 2, 3, ...), `repeat` dispatches; returns `host_output`. Unavailable when
    there is no Vulkan device, RuntimeError on any other failure."""
    env = dict(os.environ, CJ_VK_REPEAT=str(repeat))
    proc = subprocess.run([str(host), str(spv), str(records_in), str(records_out), str(count), str(stride),
                           *map(str, extra)], capture_output=True, text=True, env=env)
    if proc.returncode == 3:
        raise Unavailable(f"no Vulkan device: {proc.stderr.strip()}")
    if proc.returncode != 0:
        raise RuntimeError(f"Vulkan host failed ({proc.returncode}): {proc.stderr.strip()}")
    return host_output(proc.stdout)
