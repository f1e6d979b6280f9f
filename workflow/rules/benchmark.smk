# The embedded benchmark: ground truth by simulation, degraded initial scene, reference renders.


rule benchmark_scene:
    output:
        gt="results/scenes/{suite}/{scene}/gt/scene.json",
        gt_topology="results/scenes/{suite}/{scene}/gt/topology.json",
        initial="results/scenes/{suite}/{scene}/initial/scene.json",
        image="results/scenes/{suite}/{scene}/reference/image.png",
        segmentation="results/scenes/{suite}/{scene}/reference/segmentation.png",
        camera="results/scenes/{suite}/{scene}/reference/camera.json",
    params:
        index=scene_index,
        bench=lambda wc: {**config["benchmark"], **config["suites"][wc.suite].get("benchmark", {}),
                          "sim": config["sim"], "proxies": config["proxies"]},
        cache_dir=CACHE,
        version=V.BENCHMARK,
    log:
        "results/logs/benchmark/{suite}/{scene}.log",
    benchmark:
        "results/benchmarks/benchmark/{suite}/{scene}.tsv"
    threads: 1
    conda:
        ENV
    script:
        "../scripts/benchmark_scene.py"
