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
