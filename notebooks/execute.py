"""Execute the notebooks headless (`make notebooks`); exit 1 if any cell of any notebook fails.

    python notebooks/execute.py                 # full runs, outputs into notebooks/NAME.ipynb
    python notebooks/execute.py --quick         # or CAUSTICS_JAX_QUICK=1: outputs into build/notebooks/
    python notebooks/execute.py --quick irradiance

Each notebook's source is its Jupytext percent script `notebooks/NAME.py`; the paired
`notebooks/NAME.ipynb` (same cells, with outputs) is the executed copy committed for
reading without running. A full run rewrites those copies; a quick run (small lane and
photon counts, what CI runs) writes its copies under `--out` (default `build/notebooks`,
git-ignored) and never touches the committed ones. Cells run with the notebook's folder
as the working directory, in a kernel of this Python (`python3`, from ipykernel).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
NOTEBOOKS = ("solver_comparison", "kernel_accuracy", "irradiance", "shader_reference_data", "your_own_mesh",
             "claims")


def execute(name: str, out_dir: Path, timeout: int) -> tuple[bool, float, Path]:
    """Run `notebooks/<name>.py` top to bottom; write the executed `.ipynb` into `out_dir`."""
    import jupytext
    import nbclient

    nb = jupytext.read(HERE / f"{name}.py")
    n_code = sum(c.cell_type == "code" for c in nb.cells)
    t0 = time.perf_counter()
    last = [t0]

    def done(cell, cell_index, **_):  # one line per code cell: where a slow run spends its time
        if cell.cell_type == "code":
            now = time.perf_counter()
            print(f"  {name} [{cell.execution_count}/{n_code}] {now - last[0]:.0f} s", flush=True)
            last[0] = now

    # The kernel application logs errors only: at its default level every start warns that
    # its loopback TCP traffic is unencrypted, noise on one machine. Warnings raised by the
    # cells are not the application's log: they still reach the cells' outputs.
    client = nbclient.NotebookClient(nb, timeout=timeout, kernel_name="python3", on_cell_executed=done,
                                     resources={"metadata": {"path": str(HERE)}},
                                     extra_arguments=["--IPKernelApp.log_level=ERROR"])
    ok = True
    try:
        client.execute()
    except nbclient.exceptions.CellExecutionError as exc:
        ok = False
        print(f"{name}: a cell failed:\n{exc}", file=sys.stderr)
    except nbclient.exceptions.CellTimeoutError as exc:
        ok = False
        print(f"{name}: a cell ran past {timeout} s:\n{exc}", file=sys.stderr)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"{name}.ipynb"
    jupytext.write(nb, path)
    return ok, time.perf_counter() - t0, path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("names", nargs="*", default=[], metavar="NAME",
                    help=f"notebooks to run (default: all of {', '.join(NOTEBOOKS)})")
    ap.add_argument("--quick", action="store_true", help="CAUSTICS_JAX_QUICK=1: small lane and photon counts")
    ap.add_argument("--out", default=None,
                    help="where the executed .ipynb go (default: notebooks/ for a full run, "
                         "build/notebooks/ for --quick)")
    ap.add_argument("--timeout", type=int, default=3600, help="seconds per cell")
    args = ap.parse_args(argv)
    unknown = [n for n in args.names if n not in NOTEBOOKS]
    if unknown:
        ap.error(f"unknown notebook(s) {unknown}; choose from {', '.join(NOTEBOOKS)}")
    args.quick = args.quick or os.environ.get("CAUSTICS_JAX_QUICK", "") not in ("", "0")
    if args.quick:
        os.environ["CAUSTICS_JAX_QUICK"] = "1"  # the kernel inherits the environment
    else:
        os.environ.pop("CAUSTICS_JAX_QUICK", None)
    out_dir = Path(args.out) if args.out else (ROOT / "build" / "notebooks" if args.quick else HERE)
    failed = []
    for name in args.names or NOTEBOOKS:
        ok, seconds, path = execute(name, out_dir, args.timeout)
        size = path.stat().st_size / 1024
        print(f"{name}: {'ok' if ok else 'FAILED'} in {seconds:.0f} s -> {path} ({size:.0f} KiB)", flush=True)
        if not ok:
            failed.append(name)
    if failed:
        print(f"notebooks failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
