"""Snakemake script: the metrics files of every method of one scene (phiscene.metrics.evaluate)."""

from pathlib import Path

from phiscene.pipeline import run_metrics
from phiscene.plugins import load_plugins
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
inp = sm.input
name = f"metrics {sm.wildcards.scene}"
with job(name, sm.log[0], sm.threads, failure_outputs=sm.output):
    load_plugins(sm.config.get("plugins"))  # registrations of config plugins, in this job's process
    tasks = [{"method": t["method"], "scene": inp[f"scene_{t['method']}"], "out": out, "sections": t["sections"],
              "proxies": inp[f"proxies_{t['method']}"] if t["own_proxies"] else None, "align": t["align"]}
             for t, out in zip(sm.params.tasks, sm.output)]
    run_metrics(tasks=tasks, settings=dict(sm.params.settings), proxies_path=inp.get("proxies"), gt_path=inp.get("gt"),
                initial_path=inp.get("initial"),
                reference_dir=Path(inp.camera).parent if "camera" in inp.keys() else None,
                cache_dir=sm.params.cache_dir, name=name)
