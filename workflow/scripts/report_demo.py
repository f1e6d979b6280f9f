"""Snakemake script: the demo GIF of one scene wrapped in an HTML page (the report shows GIFs only as downloads)."""

from phiscene.report import gif_page
from phiscene.runner import job

sm = snakemake  # noqa: F821 (injected by Snakemake)
with job(f"report demo {sm.wildcards.suite}/{sm.wildcards.scene}", sm.log[0], sm.threads):
    gif_page(sm.input.gif, sm.output[0], sm.params.title, summary_json=sm.input.summary)
