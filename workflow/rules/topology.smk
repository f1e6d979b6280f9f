# Support graph + placement order of the initial scene, one file per topology backend.


rule topology:
    input:
        unpack(topology_inputs),
    output:
        "results/topology/{backend}/{suite}/{scene}.json",
    params:
        backend="{backend}",
        settings=topology_settings,
        attached=config["topology"].get("attached", {}),
        cache_dir=CACHE,
        version=V.TOPOLOGY,
    log:
        "results/logs/topology/{backend}/{suite}/{scene}.log",
    benchmark:
        "results/benchmarks/topology/{backend}/{suite}/{scene}.tsv"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=15,
    conda:
        ENV
    script:
        "../scripts/topology.py"
