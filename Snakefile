# phiscene: physically grounded image-to-3D scene reconstruction, as a Snakemake workflow.
# Run `snakemake -j2 results/tables/phys.csv` (or `make run`); see README.md.

import glob
import os
import sys

from snakemake.exceptions import WorkflowError
from snakemake.utils import min_version, validate

from phiscene.config import ConfigError, check_config, schema_sections
from phiscene.plugins import PluginError, load_plugins

min_version("9.0")


configfile: os.path.join(workflow.basedir, "config/config.yaml")


# An override file drops a table with `tables: {<name>: null}` (--configfile merges mappings, it cannot delete).
config["tables"] = {name: spec for name, spec in (config.get("tables") or {}).items() if spec is not None}


# Every parameter class on its section first (phiscene.config): a misspelled key fails here in one line naming
# its config path, before any job runs; then the schema checks types and ranges. Jobs that re-read this file
# (cluster executors) skip the class check: the main process has made it (it imports the stages, ~0.7 s).
try:  # modules that register tables, metrics, simulators, baselines (phiscene.plugins)
    load_plugins(config.get("plugins", []))
except PluginError as exc:
    raise WorkflowError(str(exc)) from None
if workflow.is_main_process:
    try:
        check_config(config, schema_sections(os.path.join(workflow.basedir, "config/schema.yaml")))
    except ConfigError as exc:
        raise WorkflowError(str(exc)) from None
validate(config, "config/schema.yaml")


include: "workflow/rules/common.smk"
include: "workflow/rules/benchmark.smk"
include: "workflow/rules/proxies.smk"
include: "workflow/rules/topology.smk"
include: "workflow/rules/methods.smk"
include: "workflow/rules/baseline.smk"
include: "workflow/rules/metrics.smk"
include: "workflow/rules/tables.smk"
include: "workflow/rules/export.smk"


# Method kinds with a rule file of their own (external predictions); registered baselines use baseline.smk.
for _baseline in sorted(glob.glob(os.path.join(workflow.basedir, "workflow/rules/baselines/*.smk"))):

    include: _baseline


check_method_kinds()


include: "workflow/rules/report.smk"


rule tables:  # `snakemake -j2 tables`: every configured table whose suite's data are here, runtime last
    input:
        default_table_files(),


rule all:
    default_target: True
    input:
        default_table_files(),  # every configured table whose suite's data are here, then runtime
        report_targets(),  # figures and pages of `snakemake --report results/report.html`
