"""Time the default run (``snakemake -j2 <targets>``) from an empty results/ folder.

The environment must already be installed (``make env``). The run happens in a fresh folder (a new
temporary one unless ``--workdir`` is given; its ``results/`` is emptied first), so caches are cold and
the repository's own ``results/`` is left alone. Usage::

    python benchmarks/default_run.py [--jobs 2] [--workdir DIR] [TARGET ...]

Prints wall time, and per-rule totals from the benchmark TSVs. Compare ``--jobs 1`` with ``--jobs 2``
for the parallel speed-up.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]


def rule_seconds(results: Path) -> pd.DataFrame:
    """Sum of wall seconds per stage (first folder under results/benchmarks)."""
    rows = []
    for tsv in (results / "benchmarks").rglob("*.tsv"):
        df = pd.read_csv(tsv, sep="\t")
        stage = str(tsv.relative_to(results / "benchmarks").parent.parts[0])
        rows.append({"stage": stage, "s": float(df["s"].iloc[0])})
    if not rows:
        return pd.DataFrame(columns=["jobs", "total_s", "mean_s"])
    df = pd.DataFrame(rows)
    return df.groupby("stage")["s"].agg(jobs="count", total_s="sum", mean_s="mean")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--workdir", default=None, help="run in this folder (default: a new temporary folder)")
    ap.add_argument("targets", nargs="*", default=["results/tables/phys.csv"])
    args = ap.parse_args()
    work = Path(args.workdir) if args.workdir else Path(tempfile.mkdtemp(prefix="phiscene-default-run-"))
    print(f"running in {work}", flush=True)
    results = work / "results"
    if results.exists():
        shutil.rmtree(results)
    cmd = [sys.executable, "-m", "snakemake", "-s", str(ROOT / "Snakefile"), "--directory", str(work),
           f"-j{args.jobs}", *args.targets]
    t0 = time.perf_counter()
    res = subprocess.run(cmd)
    wall = time.perf_counter() - t0
    print(f"\n$ {' '.join(cmd)}\nexit {res.returncode}, wall {wall:.1f} s ({wall / 60:.2f} min) with -j{args.jobs}")
    print(rule_seconds(results).to_string(float_format=lambda v: f"{v:.2f}"))
    return res.returncode


if __name__ == "__main__":
    sys.exit(main())
