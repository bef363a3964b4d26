"""`caustics-jax`: the command line (`compare`, `demo`, `export`, `conformance`).

    caustics-jax demo --figure figures/solver_comparison.png   # solver comparison on the default wavy pool
    caustics-jax compare --n 20000 --dtype float32 --configs walk newton-hv --json out.json
    caustics-jax compare --scene surface.obj --n 4096          # any mesh trimesh reads (OBJ, PLY, GLB, ...)
    caustics-jax export --out refdata --count 1024 --seed 0    # shader reference data
    caustics-jax export --out mine --scene surface.obj --light 0 0 5   # your own mesh, alone
    caustics-jax conformance refdata       # run the GLSL ports on a Vulkan device against it
    caustics-jax --version

Files are written only where the command line says (`--json`, `--figure`, `--out`),
relative paths against the current directory; nothing is written by default. Long runs
show a progress bar on a terminal only (`caustics_jax.runtime.progress`).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import warnings
from pathlib import Path

from .._version import __version__
from . import compare as cmp
from .scene_file import scene_options


def _fmt(x, spec=".2e"):
    return "-" if x is None or x != x else format(x, spec)


def format_table(report: dict) -> str:
    """The comparison as a fixed-width text table, one row per configuration and dtype."""
    w = max([16] + [len(r["config"]) + 2 for r in report["rows"]])  # names never run into the dtype
    head = (f"{'config':<{w}}{'dtype':<9}{'success':>8}{'@M0':>7}{'found':>8}"
            f"{'pos med':>10}{'pos p99':>10}{'pos max':>10}{'ang med':>10}{'ang p99':>10}"
            f"{'ang max':>10}{'it med':>7}{'it p99':>7}{'compile':>9}{'solves/s':>11}")
    lines = [f"scene {report['scene']}, {report['n']} lanes "
             f"({report['lanes_crossing_surface']} cross the surface), "
             f"backend {report['platform']} ({len(report.get('devices', [])) or 1} device(s))", head, "-" * len(head)]
    for r in report["rows"]:
        pos = r["position_error_m"] or {}
        ang = r["angle_error_rad"]
        lines.append(
            f"{r['config']:<{w}}{r['dtype']:<9}{_fmt(r['success'], '.4f'):>8}"
            f"{_fmt(r['nearest_M0'], '.3f'):>7}{r['found']:>8.4f}"
            f"{_fmt(pos.get('median')):>10}{_fmt(pos.get('p99')):>10}{_fmt(pos.get('max')):>10}"
            f"{_fmt(ang['median']):>10}{_fmt(ang['p99']):>10}{_fmt(ang['max']):>10}"
            f"{r['iterations']['median']:>7.0f}{r['iterations']['p99']:>7.0f}"
            f"{r['compile_s']:>8.1f}{'c' if r.get('compile_cached') else 's'}{r['solves_per_s']:>11.0f}")
    ref = report["reference"]
    lines.append("")
    if ref:
        lines.append(f"success and position error (m) against the exhaustive float64 reference on "
                     f"{ref['lanes']} lanes ({cmp.solution_counts(ref['solutions_per_lane'])}); "
                     "@M0: returned the solution nearest M0")
    lines.append("angle error (rad): refraction-angle error of every found lane, float64 check; "
                 "compile: first call minus a steady call (c: its programs loaded from the persistent "
                 "compilation cache, none compiled; CAUSTICS_JAX_COMPILATION_CACHE=0 to measure it)")
    for q in cmp.ratios(report):
        lines.append(f"[{q['dtype']}] walk / best Newton ({q['best_newton']}) throughput ratio: "
                     f"{q['speed_ratio']:.2f}")
    for fr in report.get("frames", []):
        first = f"{fr['compile_s']:.1f} s" + (" (loaded from the compilation cache)" if fr["compile_cached"] else "")
        lines.append(f"[{fr['dtype']}] {fr['config']}: a {fr['width']}x{fr['height']} frame "
                     f"({fr['width'] * fr['height']:,} receivers) in {fr['seconds'] * 1e3:.0f} ms; "
                     f"first call's compile {first}")
    return "\n".join(lines)


def plot(report: dict, path: Path) -> None:
    """Pareto figure: time per solve against error and success, per configuration and dtype."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sweep = report["sweep"]
    configs = list(dict.fromkeys(r["config"] for r in sweep))
    colors = dict(zip(configs, plt.rcParams["axes.prop_cycle"].by_key()["color"], strict=False))
    styles = {"float32": ("o", "-"), "float64": ("s", "--")}
    fig, (ax_err, ax_ok) = plt.subplots(1, 2, figsize=(13, 5.2))
    for name in configs:
        for dtype, (marker, ls) in styles.items():
            rows = [r for r in sweep if r["config"] == name and r["dtype"] == dtype]
            if not rows:
                continue
            t = [r["us_per_solve"] for r in rows]
            e = [max(r["angle_error_rad"]["p99"], 1e-17) for r in rows]
            ax_err.plot(t, e, ls, marker=marker, color=colors[name], label=f"{name} {dtype}")
            ax_ok.plot(t, [100 * r["found"] for r in rows], ls, marker=marker,
                       color=colors[name], label=f"{name} {dtype}")
            for r, x, y in zip(rows, t, e, strict=True):
                ax_err.annotate(f"{r['tol']:.0e}", (x, y), fontsize=6, alpha=0.7,
                                xytext=(3, 2), textcoords="offset points")
    n = sweep[0]["n"] if sweep else 0
    ax_err.set(xscale="log", yscale="log", xlabel="wall time per solve (µs, CPU, batched)",
               ylabel="p99 refraction-angle error of found lanes (rad)",
               title="Error against run time over the acceptance tolerance (labels)")
    ax_ok.set(xscale="log", xlabel="wall time per solve (µs, CPU, batched)",
              ylabel="lanes with a solution found (%)",
              title="Success against run time (same sweep)")
    from matplotlib.ticker import FixedLocator, NullFormatter, ScalarFormatter

    for ax in (ax_err, ax_ok):
        ax.grid(True, which="both", alpha=0.3)
        # Plain microsecond labels at 1-2-5 steps; log minor ticks unlabelled (they collide).
        ax.xaxis.set_major_locator(FixedLocator([m * 10.0**e for e in range(-1, 5) for m in (1, 2, 5)]))
        ax.xaxis.set_major_formatter(ScalarFormatter())
        ax.xaxis.set_minor_formatter(NullFormatter())
    ax_ok.legend(fontsize=7, loc="lower right")
    fig.suptitle(f"Solver comparison on {report['scene']}, {n} lanes per point, "
                 f"backend {report['platform']}", fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=130)
    plt.close(fig)


def check_output_file(flag: str, path) -> None:
    """Refuse, before any work, an output file that could not be written after the run: a
    directory, a path below a file, or one in a directory that cannot be written
    (nothing is created here). `None` or "none": no file; "" is refused (`Path("")` is the
    current directory)."""
    if path is None or path == "none":
        return
    if not str(path):
        raise ValueError(f"{flag} must name a file, got an empty path (leave {flag} out to write none)")
    p = Path(path).expanduser()
    if p.is_dir():
        raise ValueError(f"{flag} {path} is a directory; give a file path, e.g. {p / 'out'}")
    blocker = next((q for q in p.parents if q.exists() and not q.is_dir()), None)
    if blocker is not None:
        raise ValueError(f"{flag} {path}: {blocker} is a file, not a directory")
    if p.exists():
        ok, where = os.access(p, os.W_OK), p
    else:  # created after the run, with its missing parents, in the nearest existing directory
        where = next(q for q in p.parents if q.exists())
        ok = os.access(where, os.W_OK | os.X_OK)
    if not ok:
        raise ValueError(f"{flag} {path} is not writable ({where} does not allow writing)")


def _check_figure_format(path) -> None:
    if path is None or path == "none":
        return
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.backend_bases import FigureCanvasBase

    kinds = FigureCanvasBase.get_supported_filetypes()
    suffix = Path(path).suffix.lower().lstrip(".")
    if suffix not in kinds:
        raise ValueError(f"--figure {path}: the file type is set by the suffix, one of "
                         f"{', '.join('.' + k for k in sorted(kinds))}; got {'.' + suffix if suffix else 'none'}")


#: Solver lanes per second assumed for the run-time warning: a conservative average over the
#: comparison's configurations on a 2-core CPU, the slow ones taking most of the time
#: (docs/solvers.md, "Comparison" and "Measurements behind the code"); compile and
#: reference on top.
SOLVES_PER_S = 40_000
#: Warn when the solver time alone is expected above this (s).
LONG_RUN_S = 600


def warn_if_long_compare(cfg) -> str | None:
    """The warning line for a comparison expected to run long (None when it will not)."""
    solves = cfg.expected_solves()
    seconds = solves / SOLVES_PER_S
    if seconds <= LONG_RUN_S:
        return None
    lane_bytes = cfg.n * (6 * 8 + 14 * 8)  # P, L (float64) and one Solution's fields per lane
    return (f"warning: --n {cfg.n}: about {solves:.3g} solver lanes ({len(cfg.configs)} configuration(s) x "
            f"{len(cfg.dtypes)} dtype(s) x {cfg.repeats + 1} timed calls, plus the sweep), about "
            f"{seconds / 60:.0f} min of solver time at ~{SOLVES_PER_S // 1000}k solves/s on a 2-core CPU "
            f"(compile and reference on top) and {lane_bytes / 2**20:.0f} MiB of lanes per configuration; "
            "Ctrl-C stops it")


def _compare(args) -> int:
    if args.cpu_devices is not None:  # before any JAX work: the CPU backend reads it when it starts
        from ..runtime.blocks import use_cpu_devices

        use_cpu_devices(_cpu_devices_arg(args.cpu_devices))
    opts = scene_options(args, {"scene": "wavy", "light": None, "floor_depth": None, "eta": 1.333,
                                "triangles": 8192})
    cfg = cmp.CompareConfig(
        scene=opts["scene"], n_triangles=opts["triangles"], n=args.n, dtypes=tuple(args.dtype),
        configs=tuple(args.configs), ref_n=args.ref_n, sweep_n=args.sweep_n,
        sweep=not args.no_sweep, repeats=args.repeats, eta=opts["eta"], seed=args.seed, light=opts["light"],
        floor_depth=opts["floor_depth"], frame=_frame_arg(args.frame))
    # Everything a user can get wrong is refused here, before the run (minutes), not after it.
    cfg.validate()
    check_output_file("--json", args.json)
    check_output_file("--figure", args.figure)
    _check_figure_format(args.figure)
    warning = warn_if_long_compare(cfg)
    if warning:
        print(f"caustics-jax {args.command}: {warning}", file=sys.stderr)
    try:
        report = cmp.run(cfg)
    except ValueError as exc:
        print(f"caustics-jax compare: {exc}", file=sys.stderr)
        return 2
    print(format_table(report))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(report, indent=1, default=str))
        print(f"wrote {args.json}")
    if report["sweep"] and args.figure not in (None, "none"):
        plot(report, Path(args.figure))
        print(f"wrote {args.figure}")
    if not args.json and args.figure in (None, "none"):
        print("no files written (--json PATH and --figure PATH write the results and the Pareto figure)")
    return 0


def _frame_arg(value: str) -> tuple[int, int] | None:
    """`--frame WxH` as `(W, H)`, `none` as None."""
    if value in (None, "none"):
        return None
    try:
        w, h = (int(x) for x in value.lower().split("x"))
    except ValueError:
        raise ValueError(f"--frame must be WxH (e.g. 960x720) or 'none', got {value!r}") from None
    return (w, h)


def _cpu_devices_arg(value: str) -> int | str:
    if value == "all":
        return value
    try:
        return int(value)
    except ValueError:
        raise ValueError(f"--cpu-devices must be a positive integer or 'all', got {value!r}") from None


def _add_scene_args(p: argparse.ArgumentParser) -> None:
    """The scene options compare and export share (app/scene_file.py)."""
    p.add_argument("--light", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"),
                   help="a point light (m) replacing the scene's (default: the scene's own; a mesh file's "
                        "stands 0.75 W above it, W its width)")
    p.add_argument("--sun", type=float, nargs=3, default=None, metavar=("DX", "DY", "DZ"),
                   help="a directional light instead: the direction its rays travel (the sun overhead is "
                        "0 0 -1; caustics_jax.Directional)")
    p.add_argument("--floor-depth", type=float, default=None, metavar="D",
                   help="the receivers' floor, D m below the surface (default: the scene's; W / 4 for a mesh file)")
    p.add_argument("--eta", type=float, default=None, help="eta_in / eta_out (default: 1.333, water)")
    p.add_argument("--scene-file", default=None, metavar="FILE.toml",
                   help="a TOML scene description (scene, light or sun, floor_depth, eta, triangles, lanes); flags "
                        "given here win over it (docs/export.md, 'Your own mesh')")


def _add_compare_args(p: argparse.ArgumentParser, frame: str = "none") -> None:
    p.add_argument("--scene", default=None, metavar="NAME|PATH",
                   help=f"a named scene ({', '.join(sorted(cmp.SCENES))}) or a mesh file trimesh reads "
                        f"({', '.join(cmp.MESH_SUFFIXES)}): floor and light placed around it as documented "
                        "in caustics_jax.surface.scenes.scene_around (default: wavy)")
    _add_scene_args(p)
    p.add_argument("--triangles", type=int, default=None, help="surface tessellation (default: 8192)")
    p.add_argument("--n", type=int, default=100_000, help="receiver lanes (default: %(default)s)")
    p.add_argument("--dtype", nargs="+", default=["float32", "float64"],
                   choices=["float32", "float64"], help="precisions to run (default: both)")
    p.add_argument("--configs", nargs="+", default=list(cmp.DEFAULT_CONFIGS),
                   help=f"solver configurations, of {sorted(cmp.CONFIGS)} (default: {' '.join(cmp.DEFAULT_CONFIGS)})")
    p.add_argument("--ref-n", type=int, default=1024,
                   help="lanes checked against the exhaustive reference (0: none; default: %(default)s)")
    p.add_argument("--sweep-n", type=int, default=8192, help="lanes per Pareto sweep point (default: %(default)s)")
    p.add_argument("--no-sweep", action="store_true", help="skip the tolerance sweep and figure")
    p.add_argument("--repeats", type=int, default=2, help="timed calls per measurement (default: %(default)s)")
    p.add_argument("--cpu-devices", default=None, metavar="N|all",
                   help="split the CPU into N JAX devices ('all': one per core, at most 8) so every core runs lanes "
                        "(default: JAX's one CPU device; `make demo` passes 'all')")
    p.add_argument("--frame", default=frame, metavar="WxH|none",
                   help="also time one frame of W x H receivers per configuration, seed 001's unit "
                        "(default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="receiver and reference seed (default: %(default)s)")
    p.add_argument("--json", default=None, help="write the full results as JSON to this path (default: none)")
    p.add_argument("--figure", default=None,
                   help="write the Pareto figure (PNG) to this path (default: none)")


def _selection(named, everything) -> list[str] | None:
    """`--kernels` / `--scenes` as given: None when absent, [] for `none`, all for `all`."""
    if named is None:
        return None
    if named == ["none"]:
        return []
    return list(everything) if named == ["all"] else list(dict.fromkeys(named))  # a name given twice: once


#: Largest std430 binary per kernel: a Vulkan storage buffer addresses at most 2^32 bytes
#: (`maxStorageBufferRange` is a uint32), so a larger `<kernel>.bin` could not be bound.
MAX_BINARY_BYTES = 2**32 - 1
#: Export records per second assumed for the warning: the low end of a loaded 2-core CPU's
#: rate (docs/export.md, "Measurements behind the code").
EXPORT_RECORDS_PER_S = 2_000
#: Warn when an export is expected to write more than this or run longer than `LONG_RUN_S`.
LARGE_EXPORT_BYTES = 2**28


def export_size_warning(kernels, count: int, lanes: int, n_scenes: int) -> str | None:
    """Refuse (`ValueError`) a `--count` whose binary no storage buffer can hold; return a
    warning line with the expected size and time when the export is large, else None."""
    from ..export import KERNELS
    from ..export.records import layout

    strides = {k: layout(KERNELS[k].fields)[1] for k in kernels}
    too_big = [k for k, stride in strides.items() if stride * count > MAX_BINARY_BYTES]
    if too_big:
        raise ValueError(f"--count {count} makes {too_big[0]}.bin {strides[too_big[0]] * count / 2**30:.1f} GiB, above "
                         f"the 4 GiB a Vulkan storage buffer can address; use --count <= "
                         f"{MAX_BINARY_BYTES // max(strides.values())}")
    size = sum(strides.values()) * count
    seconds = len(kernels) * count / EXPORT_RECORDS_PER_S + n_scenes * lanes / SOLVES_PER_S
    if size <= LARGE_EXPORT_BYTES and seconds <= LONG_RUN_S:
        return None
    return (f"warning: --count {count}: about {size / 2**20:.0f} MiB of binaries for {len(kernels)} kernel(s) and "
            f"about {seconds / 60:.0f} min at ~{EXPORT_RECORDS_PER_S} records/s per kernel on a 2-core CPU")


def _export(args) -> int:
    from .. import export

    opts = scene_options(args, {"scene": None, "light": None, "floor_depth": None, "eta": None, "lanes": 256})
    own = None
    if opts["scene"] is not None:  # the user's mesh: exported alone unless kernels or scenes are named too
        own = export.mesh_file_scene(opts["scene"], light=opts["light"], floor_depth=opts["floor_depth"],
                                     eta=1.333 if opts["eta"] is None else opts["eta"])
    elif opts["light"] is not None or opts["floor_depth"] is not None or opts["eta"] is not None:
        raise ValueError("--light, --sun, --floor-depth and --eta place a mesh of your own: give it with --scene PATH "
                         "(or `scene = ...` in --scene-file); the built-in scenes keep their own")
    kernels = _selection(args.kernels, export.KERNELS)
    scenes = _selection(args.scenes, export.SCENES)
    if kernels is None and scenes is None and own is None:  # nothing named: everything
        kernels, scenes = list(export.KERNELS), list(export.SCENES)
    kernels, scenes = kernels or [], scenes or []  # one group named: only that one
    if not kernels and not scenes and own is None:  # (`--scenes none` alone had written 0 files and exited 0)
        print("caustics-jax export: nothing to export: the selection names no kernel and no scene "
              "(`--scenes none` alone exports no kernel either; name the kernels, or 'all')", file=sys.stderr)
        return 2
    n_scenes = len(scenes) + (own is not None)
    if args.count >= 4 and all(k in export.KERNELS for k in kernels):  # else export() says what is wrong
        warning = export_size_warning(kernels, args.count, opts["lanes"], n_scenes)
        if warning:
            print(f"caustics-jax export: {warning}", file=sys.stderr)
    try:
        written = export.export(args.out, kernels=kernels, count=args.count, seed=args.seed, scenes=scenes,
                                lanes=opts["lanes"], extra_scenes=[own] if own is not None else [],
                                solvers=args.solvers, newton=_newton_options(args.newton_initial_step))
    except ValueError as exc:
        print(f"caustics-jax export: {exc}", file=sys.stderr)
        return 2
    names = scenes + ([own.name] if own is not None else [])
    print(f"wrote {len(written)} files to {args.out} (kernels: {', '.join(kernels) or 'none'}; "
          f"scenes: {', '.join(names) or 'none'})")
    return 0


def _newton_options(initial_step: float):
    """The exported Newton: `export.NEWTON` with the first step size `initial_step` (1: full
    steps, `newton-hv-step`; 0.1: Cycles' MNEE step control)."""
    from ..solvers import Newton

    return Newton(stepping="one_step", constraint="half_vector", initial_step=initial_step)


def _conformance(args) -> int:
    from ..shaders import conformance

    if not args.data:  # Path("") would read the current directory
        raise ValueError("data must name the directory `caustics-jax export` wrote, got an empty path")
    check_output_file("--json", args.json)
    argv = [args.data] + (["--kernels", *args.kernels] if args.kernels else [])
    argv += ["--scenes", *args.scenes] if args.scenes else []
    return conformance.main(argv + (["--json", args.json] if args.json else []), prog="caustics-jax conformance")


def _add_export_args(p: argparse.ArgumentParser) -> None:
    from ..export import KERNELS, SCENES
    from ..export.scene_records import SOLVERS

    p.add_argument("--out", required=True, help="output directory (created if missing)")
    p.add_argument("--kernels", nargs="+", default=None, metavar="KERNEL",
                   help=f"kernels to export, 'all' or 'none' (default: all of {', '.join(KERNELS)}, unless only "
                        "--scenes is given)")
    p.add_argument("--scenes", nargs="+", default=None, metavar="SCENE",
                   help=f"scenes to export, 'all' or 'none' (default: all of {', '.join(SCENES)}, unless only "
                        "--kernels is given)")
    p.add_argument("--count", type=int, default=256,
                   help="random + planted records per kernel (a quarter planted; adversarial cases come on "
                        "top; default: %(default)s)")
    p.add_argument("--scene", default=None, metavar="PATH",
                   help="your own mesh file (any format trimesh reads), exported alone as one scene named after "
                        "the file's stem, placed as `compare --scene PATH` places it; with --light, "
                        "--floor-depth, --eta or --scene-file")
    _add_scene_args(p)
    p.add_argument("--lanes", type=int, default=None, help="lanes per scene (default: 256)")
    p.add_argument("--solvers", nargs="+", default=list(SOLVERS), choices=list(SOLVERS),
                   help="solvers whose scene files are written: <scene>.json (walk), <scene>.newton.json (one-step "
                        "Newton) (default: both)")
    p.add_argument("--newton-initial-step", type=float, default=1.0, metavar="BETA",
                   help="the exported Newton's first step size, in (0, 1]: 1 full Newton steps (newton-hv-step), "
                        "0.1 Cycles' MNEE step control (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="generator seed: same seed, same bytes (default: %(default)s)")


@contextlib.contextmanager
def _warnings_as_lines(prog: str):
    """Warnings stay warnings (filters apply as usual), but are shown as one line
    `prog: warning: message`: from the command line, the caller the package names is the
    entry-point script, whose path told the user nothing."""
    shown = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        name = "warning" if category is UserWarning else category.__name__
        print(f"{prog}: {name}: {message}", file=sys.stderr if file is None else file)

    warnings.showwarning = show
    try:
        yield
    finally:
        warnings.showwarning = shown


class _Parser(argparse.ArgumentParser):
    """argparse with its usage errors on one line (the usage itself is what `--help` is for)."""

    def error(self, message):
        self.exit(2, f"{self.prog}: {message} (see {self.prog} --help)\n")


def main(argv=None) -> int:
    parser = _Parser(prog="caustics-jax", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    _add_compare_args(sub.add_parser(
        "compare", help="solver comparison: table, optional JSON and Pareto figure"))
    _add_compare_args(sub.add_parser(
        "demo", help="the main job, the same as `compare` with its defaults (the default wavy pool) and a "
                     "960x720 frame timed; `make demo` adds --cpu-devices all --figure "
                     "figures/solver_comparison.png --json figures/solver_comparison.json"), frame="960x720")
    _add_export_args(sub.add_parser(
        "export", help="reference data for shader tests: <kernel>.json + .bin per kernel, <scene>.json + .bin "
                       "per scene, C headers"))
    conf = sub.add_parser("conformance", help="run the GLSL ports on a Vulkan device against exported data")
    conf.add_argument("data", help="directory written by `caustics-jax export`")
    conf.add_argument("--kernels", nargs="+", default=None, metavar="KERNEL",
                      help="kernels to check (default: every kernel exported in DATA)")
    conf.add_argument("--scenes", nargs="+", default=None, metavar="SCENE",
                      help="scenes to check (default: every scene exported in DATA)")
    conf.add_argument("--json", default=None, help="write the per-kernel and per-scene reports as JSON here")
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # usage errors (one line, `_Parser.error`) return 2; --help, --version exit 0
        if not exc.code:
            raise
        return exc.code if isinstance(exc.code, int) else 2
    run = {"export": _export, "conformance": _conformance}.get(args.command, _compare)
    # A user error is one line on stderr and exit status 2, never a traceback
    # (docs/input_contract.md "Command line"); files that cannot be written: status 1.
    try:
        with _warnings_as_lines(f"caustics-jax {args.command}"):
            return run(args)
    except ValueError as exc:
        print(f"caustics-jax {args.command}: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"caustics-jax {args.command}: {exc.strerror or exc}: {exc.filename or ''}".rstrip(": "),
              file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
