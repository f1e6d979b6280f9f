# Helpers of the report rules (report.smk): which tables, figures and scenes the report shows.

#: Tables the report shows (default tables whose kind the report shows), in page order; the ones with a bar chart.
REPORT_TABLES = [t for t in default_tables() if table_kind(t).report]
BAR_TABLES = [t for t in REPORT_TABLES if table_kind(t).bar_columns()]


def drift_figures():
    """Drift distributions: simulator (phiscene.metrics.drift) -> (its metrics section, the first report table
    reading that section, whose suite and methods the figure shows)."""
    from phiscene.metrics.drift import SIMULATORS

    out = {}
    for name, sim in SIMULATORS.items():
        shown = [t for t in REPORT_TABLES if sim.section in table_kind(t).metric_sections()]
        if shown:
            out[name] = (sim.section, shown[0])
    return out


DRIFT_FIGURES = drift_figures()
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


def report_table_params(tables):
    """Kinds and report titles of tables (for names that are not their kind: a kind shown on another suite)."""
    from phiscene.table_registry import heading_of

    kinds = {t: table_kind(t).name for t in tables}
    titles = {t: f"{table_kind(t).title} ({config['tables'][t]['suite']} suite)" for t in tables if kinds[t] != t}
    return {"kinds": kinds, "titles": titles}


def table_files(tables):
    """Named inputs of a table page: csv_<table> and md_<table> of each table."""
    return {
        **{f"csv_{t}": f"results/tables/{t}.csv" for t in tables},
        **{f"md_{t}": f"results/tables/{t}.md" for t in tables},
    }


def front_table_files(wildcards):
    """Named inputs of the report's front page: every report table."""
    return table_files(REPORT_TABLES)


def page_tables(wildcards):
    """The one table of a table page."""
    return [wildcards.table]


def page_table_files(wildcards):
    """Named inputs of a table page."""
    return table_files(page_tables(wildcards))


def page_table_params(wildcards):
    """Kind and title of a table page's table."""
    return report_table_params(page_tables(wildcards))


def bar_table_kind(wildcards):
    """The kind of a bar figure's table."""
    return table_kind(wildcards.table).name


def drift_figure_inputs(wildcards):
    """Metrics files of the table a drift figure shows."""
    return table_inputs(DRIFT_FIGURES[wildcards.engine][1])


def drift_figure_methods(wildcards):
    """Methods of the table a drift figure shows."""
    return table_rows(DRIFT_FIGURES[wildcards.engine][1])


def drift_figure_section(wildcards):
    """The metrics section holding a drift figure's simulator."""
    return DRIFT_FIGURES[wildcards.engine][0]


def report_method_scene(wildcards):
    """The report method's scene of a job's suite and scene."""
    return method_scene(REPORT_METHOD, wildcards.suite, wildcards.scene)
