# The HTML report: `snakemake --report results/report.html` after the workflow has run.
# Pages and figures it shows (rule all makes them all; helpers in report_common.smk, captions in
# workflow/report/*.rst):
#   front page      the paper's tables (results/report/tables.html, embedded by workflow/report/workflow.rst)
#   Tables          one HTML page per table (best bold, second underlined, CSV + Markdown downloads)
#   Figures         per-method bars per table, per-scene drift distributions (pybullet, MuJoCo)
#   Scenes          per scene: before/after renders + support graph, an interactive offline 3D viewer
#   Demo            the demo GIFs (results/demo/{suite}/{scene}.gif), when the workflow makes them
#   Cost growth     time and peak memory per stage against scene size (benchmarks/scaling.py), if report.scaling
# No benchmark: TSVs here: the runtime table (an input of the report) reads every TSV in results/benchmarks/.


report: "../report/workflow.rst"


include: "report_common.smk"


rule report_front_tables:
    input:
        unpack(front_table_files),
    output:
        "results/report/tables.html",
    params:
        tables=REPORT_TABLES,
        names=report_table_params(REPORT_TABLES),
        title="phiscene tables",
        fragment=True,
        version=V.REPORT,
    log:
        "results/logs/report/tables.log",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/report_tables.py"


rule report_table:
    input:
        unpack(page_table_files),
    output:
        report(
            "results/report/tables/{table}.html",
            caption="../report/table.rst",
            category="Tables",
            labels={"table": "{table}"},
        ),
    wildcard_constraints:
        table=alternation(REPORT_TABLES),
    params:
        tables=page_tables,
        names=page_table_params,
        title="{table} table",
        fragment=False,
        version=V.REPORT,
    log:
        "results/logs/report/tables/{table}.log",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/report_tables.py"


rule report_bars:
    input:
        "results/tables/{table}.csv",
    output:
        report(
            "results/report/figures/{table}_bars.png",
            caption="../report/bars.rst",
            category="Figures",
            subcategory="Metrics per method",
            labels={"table": "{table}"},
        ),
    wildcard_constraints:
        table=alternation(BAR_TABLES),
    params:
        table="{table}",
        kind=bar_table_kind,
        version=V.REPORT,
    log:
        "results/logs/report/bars/{table}.log",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/report_bars.py"


rule report_drift:
    input:
        unpack(drift_figure_inputs),
    output:
        report(
            "results/report/figures/drift_{engine}.png",
            caption="../report/drift.rst",
            category="Figures",
            subcategory="Drift per scene",
            labels={"simulator": "{engine}"},
        ),
    wildcard_constraints:
        engine=alternation(list(DRIFT_FIGURES)),
    params:
        methods=drift_figure_methods,
        section=drift_figure_section,
        seed=config["benchmark"]["seed"],
        version=V.REPORT,
    log:
        "results/logs/report/drift_{engine}.log",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/report_drift.py"


rule report_scene:
    input:
        initial="results/scenes/{suite}/{scene}/initial/scene.json",
        method=report_method_scene,
        camera="results/scenes/{suite}/{scene}/reference/camera.json",
        topology=report_topology,
    output:
        report(
            "results/report/scenes/{suite}/{scene}.png",
            caption="../report/scene.rst",
            category="Scenes",
            subcategory="{suite}",
            labels={"scene": "{scene}", "view": "renders + support graph"},
        ),
    params:
        method=REPORT_METHOD,
        title="{suite}/{scene}",
        version=V.REPORT,
    log:
        "results/logs/report/scenes/{suite}/{scene}.log",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/report_scene.py"


rule report_viewer:
    input:
        scene=report_method_scene,
    output:
        report(
            "results/report/viewers/{suite}/{scene}.html",
            caption="../report/viewer.rst",
            category="Scenes",
            subcategory="{suite}",
            labels={"scene": "{scene}", "view": "3D viewer"},
        ),
    params:
        method=REPORT_METHOD,
        title=f"{{suite}}/{{scene}}: {REPORT_METHOD}",
        color_by="rgb",
        version=V.REPORT,
    log:
        "results/logs/report/viewers/{suite}/{scene}.log",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/report_viewer.py"


rule report_demo:
    input:
        gif="results/demo/{suite}/{scene}.gif",
        summary="results/demo/{suite}/{scene}.json",
    output:
        report(
            "results/report/demo/{suite}/{scene}.html",
            caption="../report/demo.rst",
            category="Demo",
            labels={"suite": "{suite}", "scene": "{scene}"},
        ),
    params:
        title="{suite}/{scene}: a ball thrown into the settled scene",
        version=V.REPORT,
    log:
        "results/logs/report/demo/{suite}/{scene}.log",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/report_demo.py"


rule scaling_benchmark:
    # Cost growth with scene size. It times every stage, so it claims every core and runs alone.
    output:
        csv="results/bench/scaling.csv",
        png=report("results/bench/scaling.png", caption="../report/scaling.rst", category="Cost growth"),
    params:
        script=os.path.join(workflow.basedir, "benchmarks/scaling.py"),
        sizes=config["report"]["scaling"],
        settings=phiscene.config.scaling_settings(config),
        version=V.REPORT,
    log:
        "results/logs/bench/scaling.log",
    threads: workflow.resource_settings.cores or 1  # every local core (alone on the machine); 1 on a cluster
    resources:
        mem_mb=4000,
        runtime=60,
    conda:
        ENV
    script:
        "../scripts/scaling_benchmark.py"
