"""Snakemake script: run benchmarks/scaling.py (cost growth with scene size) with the workflow's settings."""

import subprocess
import sys
import tempfile
from pathlib import Path

import yaml

sm = snakemake  # noqa: F821 (injected by Snakemake)
out = Path(sm.output.csv).parent
with tempfile.TemporaryDirectory() as tmp, open(sm.log[0], "w") as log:
    config = Path(tmp) / "config.yaml"
    config.write_text(yaml.safe_dump(dict(sm.params.settings)))
    cmd = [sys.executable, sm.params.script, "--rebuild", "--config", str(config), "--out", str(out),
           "--sizes", *map(str, sm.params.sizes)]
    log.write(" ".join(cmd) + "\n")
    log.flush()
    if subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT).returncode:
        sys.exit(f"benchmarks/scaling.py failed: see {sm.log[0]}")
