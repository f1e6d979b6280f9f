# Methods: each writes results/methods/{method}/{suite}/{scene}/scene.json (the shared contract).
# Reference rows (gt, initial) need no job: their scene is the benchmark scene (method_scene in common.smk).
# phi_scene-kind methods ground the initial scene.


rule phi_scene:
    input:
        unpack(phi_scene_inputs),
    output:
        scene="results/methods/{method}/{suite}/{scene}/scene.json",
        log_json="results/methods/{method}/{suite}/{scene}/assembly.json",
    wildcard_constraints:
        method=alternation(methods_of_kind("phi_scene")),
    params:
        assembly=method_assembly,
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
        "../scripts/ground.py"
