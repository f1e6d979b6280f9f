# Baseline lift_sim: PAT3D-style: single-parent support tree, children lifted above their parent's box, then joint simulation.


rule baseline_lift_sim:
    input:
        scene="results/scenes/{suite}/{scene}/initial/scene.json",
        proxies="results/proxies/{suite}/{scene}.npz",
        topology=lambda wc: f"results/topology/{config['methods'][wc.method]['topology']}/{wc.suite}/{wc.scene}.json",
    output:
        scene="results/methods/{method}/{suite}/{scene}/scene.json",
        log_json="results/methods/{method}/{suite}/{scene}/baseline.json",
    wildcard_constraints:
        method=alternation(methods_of_kind("lift_sim")),
    params:
        kind="lift_sim",
        settings=lambda wc: config["methods"][wc.method].get("params", {}),
        sim=config["sim"],
        cache_dir=CACHE,
        version=V.GROUND,
    log:
        "results/logs/methods/{method}/{suite}/{scene}.log",
    benchmark:
        "results/benchmarks/methods/{method}/{suite}/{scene}.tsv"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=30,
    conda:
        ENV
    script:
        "../../scripts/baseline.py"
