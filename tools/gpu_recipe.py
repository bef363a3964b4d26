"""Conformance and GLSL throughput on a real Vulkan GPU, where one is present.

    python tools/gpu_recipe.py [--device TEXT] [--lanes 4096] [--out gpu_run]

1. Builds the Vulkan host (`caustics_jax/shaders/host.c`) and lists the Vulkan devices it
   sees (index, type, driver version, API version, subgroup size, name).
2. Picks the first device whose name contains `--device` (default: the first that is not
   a CPU driver such as lavapipe). Without one it prints why and exits 0: nothing here
   requires a GPU, and CI keeps lavapipe.
3. Exports every scene for the walk and the one-step Newton (`caustics-jax export --scenes
   all --kernels none`, `--lanes` per scene) and every kernel, runs `caustics-jax
   conformance` on that device (`CJ_VK_DEVICE_NAME`), and then
   `experiments/glsl_throughput.py` on the same files.
4. Writes into `--out`: `devices.json` (the list, the chosen device and its driver),
   `conformance.json`, `glsl_throughput.json` and `glsl_throughput.png` (the figure of
   docs/export.md "The race in GLSL", measured on the GPU; figures/ is not touched).

Exit status: 0 when everything passed or no GPU is present, 1 when conformance failed.
docs/export.md "Running on a GPU" says what a GPU run has to confirm.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def pick(devices: list[dict], wanted: str | None) -> dict | None:
    """The first device whose name contains `wanted`, else the first that is not a CPU driver."""
    if wanted:
        return next((d for d in devices if wanted in d["name"]), None)
    return next((d for d in devices if d["type"] != "cpu"), None)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default=None, help="a text the device's name contains (default: the first GPU)")
    ap.add_argument("--lanes", type=int, default=4096, help="lanes per scene (default: %(default)s)")
    ap.add_argument("--out", default="gpu_run", help="output directory (default: %(default)s)")
    ap.add_argument("--throughput-scenes", nargs="+", default=None, help="scenes of the throughput run")
    args = ap.parse_args(argv)

    from caustics_jax.shaders import vulkan as vk

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    try:
        host = vk.build_host(out / "work")
        devices = vk.list_devices(host)
    except vk.Unavailable as exc:
        print(f"gpu_recipe: skipped, no Vulkan toolchain or device: {exc}")
        return 0
    for d in devices:
        print(f"  [{d['index']}] {d['name']} ({d['type']}, driver {d['driver_version']}, Vulkan {d['api_version']}, "
              f"subgroup {d['subgroup_size']})")
    chosen = pick(devices, args.device)
    (out / "devices.json").write_text(json.dumps({"devices": devices, "chosen": chosen}, indent=1) + "\n")
    if chosen is None:
        what = f"no device named like {args.device!r}" if args.device else "no GPU (only CPU drivers)"
        print(f"gpu_recipe: skipped, {what}")
        return 0
    print(f"gpu_recipe: running on {chosen['name']} (driver {chosen['driver_version']})")
    os.environ["CJ_VK_DEVICE_NAME"] = chosen["name"]

    from caustics_jax.app import cli

    data = out / "data"
    if cli.main(["export", "--out", str(data), "--scenes", "all", "--lanes", str(args.lanes)]) != 0:
        return 1
    code = cli.main(["conformance", str(data), "--json", str(out / "conformance.json")])
    if code == 3:
        print("gpu_recipe: skipped, the chosen device ran no shader")
        return 0

    from experiments import glsl_throughput

    scenes = args.throughput_scenes or list(glsl_throughput.SCENE_NAMES)
    glsl_throughput.main(["--data", str(data), "--lanes", str(args.lanes), "--scenes", *scenes,
                          "--json", str(out / "glsl_throughput.json"), "--figure", str(out / "glsl_throughput.png")])
    return 1 if code else 0


if __name__ == "__main__":
    sys.exit(main())
