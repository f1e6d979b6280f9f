# Paper tables as CSV + Markdown.


rule phys_table:
    input:
        unpack(lambda wc: table_inputs("physical", "phys", config["tables"]["phys"]["methods"])),
    output:
        csv="results/tables/phys.csv",
        md="results/tables/phys.md",
    params:
        methods=config["tables"]["phys"]["methods"],
        version=V.TABLES,
    log:
        "results/logs/tables/phys.log",
    threads: 1
    conda:
        ENV
    script:
        "../scripts/phys_table.py"


rule topology_table:
    input:
        unpack(lambda wc: table_inputs("topology", "topology", config["tables"]["topology"]["backends"])),
    output:
        csv="results/tables/topology.csv",
        md="results/tables/topology.md",
    params:
        backends=config["tables"]["topology"]["backends"],
        version=V.TABLES,
    log:
        "results/logs/tables/topology.log",
    threads: 1
    conda:
        ENV
    script:
        "../scripts/topology_table.py"
