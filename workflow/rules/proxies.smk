# Convex-decomposition collision proxies of every object of a scene (backed by a content-addressed cache).


rule proxies:
    input:
        scene="results/scenes/{suite}/{scene}/initial/scene.json",
    output:
        "results/proxies/{suite}/{scene}.npz",
    params:
        proxies=suite_proxies,
        cache_dir=CACHE,
        version=V.PROXIES,
    log:
        "results/logs/proxies/{suite}/{scene}.log",
    benchmark:
        "results/benchmarks/proxies/{suite}/{scene}.tsv"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=30,
    conda:
        ENV
    script:
        "../scripts/proxies.py"


rule gt_proxies:
    # ground-truth meshes of suites whose initial meshes are reconstructions (benchmark degrade kind foundation)
    input:
        scene="results/scenes/{suite}/{scene}/gt/scene.json",
    output:
        "results/proxies/{suite}/{scene}.gt.npz",
    params:
        proxies=config["proxies"],  # the settings the benchmark verified its ground truth with (cache hits)
        cache_dir=CACHE,
        version=V.PROXIES,
    log:
        "results/logs/proxies/{suite}/{scene}.gt.log",
    benchmark:
        "results/benchmarks/proxies/{suite}/{scene}.gt.tsv"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=30,
    conda:
        ENV
    script:
        "../scripts/proxies.py"
