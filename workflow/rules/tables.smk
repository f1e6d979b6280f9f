# Paper tables as CSV + Markdown, from the per-scene metrics files (the topology table scores the graphs itself).


rule phys_table:
    input:
        unpack(lambda wc: table_inputs("phys")),
    output:
        csv="results/tables/phys.csv",
        md="results/tables/phys.md",
    params:
        methods=config["tables"]["phys"]["methods"],
        version=V.TABLES,
    log:
        "results/logs/tables/phys.log",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/phys_table.py"


rule topology_table:
    input:
        unpack(topology_table_inputs),
    output:
        csv="results/tables/topology.csv",
        md="results/tables/topology.md",
    params:
        backends=config["tables"]["topology"]["backends"],
        version=V.TABLES,
    log:
        "results/logs/tables/topology.log",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/topology_table.py"


rule crosssim_table:
    input:
        unpack(lambda wc: table_inputs("crosssim")),
    output:
        csv="results/tables/crosssim.csv",
        md="results/tables/crosssim.md",
    params:
        methods=config["tables"]["crosssim"]["methods"],
        version=V.TABLES,
    log:
        "results/logs/tables/crosssim.log",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/crosssim_table.py"


rule recon_table:
    input:
        unpack(lambda wc: table_inputs("recon")),
    output:
        csv="results/tables/recon.csv",
        md="results/tables/recon.md",
    params:
        methods=config["tables"]["recon"]["methods"],
        version=V.TABLES,
    log:
        "results/logs/tables/recon.log",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/recon_table.py"


rule runtime_table:
    input:
        # every other table: their jobs wrote the benchmark TSVs this table reads
        [f"results/tables/{t}.csv" for t in ("phys", "topology", "crosssim", "recon", "ablation")],
    output:
        csv="results/tables/runtime.csv",
        md="results/tables/runtime.md",
    params:
        benchmarks="results/benchmarks",
        version=V.TABLES,
    log:
        "results/logs/tables/runtime.log",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/runtime_table.py"


rule ablation_table:
    input:
        unpack(lambda wc: table_inputs("ablation")),
    output:
        csv="results/tables/ablation.csv",
        md="results/tables/ablation.md",
    params:
        methods=config["tables"]["ablation"]["methods"],
        version=V.TABLES,
    log:
        "results/logs/tables/ablation.log",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/ablation_table.py"


rule real_table:
    # the real suite (config tables.real): rows initial, the imported peer result(s), every grounding variant
    input:
        unpack(real_table_inputs),
    output:
        csv="results/tables/real.csv",
        md="results/tables/real.md",
        scenes="results/tables/real_scenes.csv",
    params:
        methods=config["tables"].get("real", {}).get("methods", []),
        scenes=real_table_scenes,
        version=V.TABLES,
    log:
        "results/logs/tables/real.log",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/real_table.py"
