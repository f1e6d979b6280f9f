# Baseline joint_sdf: CAST-style joint SDF: all object translations optimised together (paper Tab. 6).


rule baseline_joint_sdf:
    input:
        scene="results/scenes/{suite}/{scene}/initial/scene.json",
    output:
        scene="results/methods/{method}/{suite}/{scene}/scene.json",
        log_json="results/methods/{method}/{suite}/{scene}/baseline.json",
    wildcard_constraints:
        method=alternation(methods_of_kind("joint_sdf")),
    params:
        kind="joint_sdf",
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
