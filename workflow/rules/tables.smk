# Tables as CSV + Markdown: one generic rule for every table (phiscene.table_registry): a configured
# `tables.<name>` entry of a registered kind, or a kind that needs no config (runtime). What the rule gathers
# (metrics files, support graphs, benchmark TSVs) follows the kind.


rule table:
    input:
        unpack(table_rule_inputs),
    output:
        csv="results/tables/{table}.csv",
        md="results/tables/{table}.md",
    wildcard_constraints:
        table=alternation(table_names()),
    params:
        spec=table_params,
        version=V.TABLES,
    log:
        "results/logs/tables/{table}.log",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/table.py"


rule table_scenes:
    # per-(row, scene) values of the kinds that write them (the real-scene table)
    input:
        unpack(table_rule_inputs),
    output:
        "results/tables/{table}_scenes.csv",
    wildcard_constraints:
        table=alternation([t for t in table_names() if table_kind(t).scene_rows is not None]),
    params:
        spec=table_params,
        version=V.TABLES,
    log:
        "results/logs/tables/{table}_scenes.log",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/table.py"
