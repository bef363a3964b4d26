"""What every experiment shares: the figures folder, the plotting backend, JSON output,
progress lines, error statistics, median timing, and command-line parsing that survives Jupyter.

Experiments run headless as modules from the repository root
(`python -m experiments.stability`) or open as notebooks (jupytext `# %%` cells) with the
repository root on `sys.path`.
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import sys
import time

import jax
import numpy as np

from caustics_jax.app.reporting import log, stats  # noqa: F401  (re-exported for the experiments)

ROOT = pathlib.Path(__file__).resolve().parents[1]


def figures_dir() -> pathlib.Path:
    """`<repository>/figures`, created if missing: where figures and their JSON go."""
    path = ROOT / "figures"
    path.mkdir(exist_ok=True)
    return path


def median_time(fn, repeats: int = 1):
    """`(result, seconds)`: one untimed call (compiles for these shapes, or loads from the
    compilation cache), then the median wall time of `repeats` calls, each waited for
    (`jax.block_until_ready`)."""
    out = jax.block_until_ready(fn())
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        out = jax.block_until_ready(fn())
        times.append(time.perf_counter() - t)
    return out, float(np.median(times))


def in_ipython() -> bool:
    """True inside an IPython shell or Jupyter kernel."""
    ipython = sys.modules.get("IPython")
    return ipython is not None and ipython.get_ipython() is not None


def use_agg() -> None:
    """Draw off-screen with matplotlib's Agg backend when run as a script; inside IPython or
    Jupyter keep the kernel's backend, so figures still show inline."""
    if not in_ipython():
        import matplotlib

        matplotlib.use("Agg")


def parse_args(parser: argparse.ArgumentParser, argv=None) -> argparse.Namespace:
    """`parser.parse_args(argv)`, strict on the command line; inside IPython or Jupyter,
    whose `sys.argv` holds the kernel's own flags (`-f kernel.json`), the defaults."""
    if argv is None and in_ipython():
        argv = []
    return parser.parse_args(argv)


def run_and_write(parser: argparse.ArgumentParser, run, plot, table) -> dict:
    """An experiment's command-line run: `run(args)`, timed; the report as `<--out>.json`,
    its figure `plot(report, <--out>.png)` and its table `table(report)` printed."""
    args = parse_args(parser)
    t0 = time.perf_counter()
    report = run(args)
    report["seconds"] = time.perf_counter() - t0
    write_json(args.out + ".json", report)
    plot(report, args.out + ".png")
    print(table(report))
    log(f"wrote {args.out}.png and .json ({report['seconds']:.0f} s)")
    return report


def _json_safe(x):
    """`x` with numpy scalars and arrays as Python numbers and lists, NaN and inf as None."""
    if isinstance(x, dict):
        return {k: _json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_json_safe(v) for v in x]
    if isinstance(x, np.ndarray):
        return _json_safe(x.tolist())
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def write_json(path, obj) -> pathlib.Path:
    """Write `obj` as strict JSON (NaN and inf become null), creating the folder."""
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(_json_safe(obj), indent=1, allow_nan=False))
    return path
