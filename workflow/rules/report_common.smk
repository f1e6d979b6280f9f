# Helpers of the report rules (report.smk): which tables, figures and scenes the report shows.

#: Tables the report shows (keys of phiscene.report.TABLES), in page order; the ones with a bar chart.
REPORT_TABLES = ["phys", "crosssim", "recon", "topology", "ablation", "runtime"]
BAR_TABLES = ["phys", "crosssim", "recon", "topology", "ablation"]
#: Drift distributions: engine -> (metrics file section, the table whose suite and methods it shows).
DRIFT_FIGURES = {"pybullet": ("physical", "phys"), "mujoco": ("mujoco", "crosssim")}
REPORT_METHOD = config["report"]["method"]
if REPORT_METHOD not in config["methods"]:
    raise ValueError(f"config: report.method: unknown method {REPORT_METHOD!r}; known: {sorted(config['methods'])}")


def report_suites():
    """Suites of the tables: every scene of these gets a picture and a 3D viewer in the report."""
    return sorted(
        {spec["suite"] for spec in config["tables"].values() if "suite" in spec and suite_available(spec["suite"])}
    )


def report_topology(wildcards):
    """The support graph drawn beside a scene: the one the report method used, else the ground truth's."""
    backend = config["methods"][REPORT_METHOD].get("topology")
    if backend is None:
        return f"results/scenes/{wildcards.suite}/{wildcards.scene}/gt/topology.json"
    return f"results/topology/{backend}/{wildcards.suite}/{wildcards.scene}.json"


def demo_gifs():
    """Demo GIFs the report shows: results/demo/{suite}/{scene}.gif of `demo_scenes()` (export_common.smk)."""
    return [f"results/demo/{suite}/{scene}.gif" for suite, scene in demo_scenes()]


def report_targets():
    """Every file the report shows (rule all asks for them, so `snakemake --report` finds them made)."""
    out = ["results/report/tables.html"]
    out += [f"results/report/tables/{t}.html" for t in REPORT_TABLES]
    out += [f"results/report/figures/{t}_bars.png" for t in BAR_TABLES]
    out += [f"results/report/figures/drift_{engine}.png" for engine in DRIFT_FIGURES]
    for suite in report_suites():
        out += expand("results/report/scenes/{suite}/{scene}.png", suite=suite, scene=scene_ids(suite))
        out += expand("results/report/viewers/{suite}/{scene}.html", suite=suite, scene=scene_ids(suite))
    out += [g.replace("results/demo/", "results/report/demo/").replace(".gif", ".html") for g in demo_gifs()]
    if config["report"].get("scaling"):
        out.append("results/bench/scaling.png")
    return out


def table_files(tables):
    """Named inputs of a table page: csv_<table> and md_<table> of each table."""
    return {
        **{f"csv_{t}": f"results/tables/{t}.csv" for t in tables},
        **{f"md_{t}": f"results/tables/{t}.md" for t in tables},
    }
