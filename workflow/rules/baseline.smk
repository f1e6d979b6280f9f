# Baselines registered in phiscene.baselines.registry (the paper's Tab. 6 ones: joint_sdf, joint_sim,
# joint_sdf_sim, lift_sim): one rule for every method whose kind is registered. Its inputs follow the entry:
# the initial scene, plus the scene's proxies and the method's topology graph when the baseline needs them.


rule baseline:
    input:
        unpack(baseline_inputs),
    output:
        scene="results/methods/{method}/{suite}/{scene}/scene.json",
        log_json="results/methods/{method}/{suite}/{scene}/baseline.json",
    wildcard_constraints:
        method=alternation(registered_baseline_methods()),
    params:
        kind=method_kind,
        settings=baseline_settings,
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
        "../scripts/baseline.py"
