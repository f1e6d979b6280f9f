"""A job's thread budget reaches every pool it runs on, open3d's TBB pool included (own process each: the limits
are process-wide)."""

import subprocess
import sys

import pytest

PROBE = """
import os, sys
from phiscene.runner import set_threads, thread_budget
set_threads({threads})
from phiscene.o3d import open3d
o3d = open3d()
print(thread_budget(), o3d.utility.get_max_threads() if hasattr(o3d.utility, "get_max_threads") else -2)
"""


@pytest.mark.parametrize("threads", [1, 2])
def test_open3d_pool_takes_the_job_budget(threads):
    out = subprocess.run([sys.executable, "-c", PROBE.format(threads=threads)], capture_output=True, text=True,
                         check=True).stdout.split()
    budget, o3d_threads = int(out[0]), int(out[1])
    assert budget == threads
    if o3d_threads == -2:
        pytest.skip("this open3d has no thread limit (TBB pool before 0.19)")
    assert o3d_threads == threads


def test_budget_unset_means_every_core(monkeypatch):
    from phiscene.runner import thread_budget

    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    assert thread_budget() == -1
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    assert thread_budget() == 3
