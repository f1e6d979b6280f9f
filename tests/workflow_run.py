"""Running the workflow from a test: ``snakemake`` in a subprocess on this checkout's Snakefile."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def snakemake(workdir: Path, configfiles: list[Path], *args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    """``snakemake -s Snakefile --directory WORKDIR ARGS --configfile CONFIGFILES`` (hash seed fixed, output
    captured)."""
    cmd = [sys.executable, "-m", "snakemake", "-s", str(ROOT / "Snakefile"), "--directory", str(workdir), *args,
           "--configfile", *map(str, configfiles)]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout,
                          env={**os.environ, "PYTHONHASHSEED": "0"})
