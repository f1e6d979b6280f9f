# Baseline joint_sdf_sim: Joint SDF, then all objects simulated together to rest (paper Tab. 6).


rule baseline_joint_sdf_sim:
    input:
        scene="results/scenes/{suite}/{scene}/initial/scene.json",
        proxies="results/proxies/{suite}/{scene}.npz",
    output:
        scene="results/methods/{method}/{suite}/{scene}/scene.json",
        log_json="results/methods/{method}/{suite}/{scene}/baseline.json",
    wildcard_constraints:
        method=alternation(methods_of_kind("joint_sdf_sim")),
    params:
        kind="joint_sdf_sim",
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
