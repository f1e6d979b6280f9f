# Per-scene metrics of any method's scene.json.


rule physical_metrics:
    input:
        scene="results/methods/{method}/{suite}/{scene}/scene.json",
        proxies=proxies_of,
    output:
        "results/metrics/physical/{method}/{suite}/{scene}.json",
    params:
        physical=config["metrics"]["physical"],
        sim=config["sim"],
        cache_dir=CACHE,
        version=V.METRICS,
    log:
        "results/logs/metrics/physical/{method}/{suite}/{scene}.log",
    benchmark:
        "results/benchmarks/metrics/physical/{method}/{suite}/{scene}.tsv"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=15,
    conda:
        ENV
    script:
        "../scripts/physical_metrics.py"


rule topology_metrics:
    input:
        predicted="results/topology/{backend}/{suite}/{scene}.json",
        gt="results/scenes/{suite}/{scene}/gt/topology.json",
    output:
        "results/metrics/topology/{backend}/{suite}/{scene}.json",
    params:
        version=V.METRICS,
    log:
        "results/logs/metrics/topology/{backend}/{suite}/{scene}.log",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    conda:
        ENV
    script:
        "../scripts/topology_metrics.py"


rule mujoco_metrics:
    input:
        scene="results/methods/{method}/{suite}/{scene}/scene.json",
        proxies=proxies_of,
    output:
        "results/metrics/mujoco/{method}/{suite}/{scene}.json",
    params:
        physical=config["metrics"]["physical"],
        sim=config["sim"],
        mujoco=config["metrics"]["mujoco"],
        version=V.METRICS,
    log:
        "results/logs/metrics/mujoco/{method}/{suite}/{scene}.log",
    benchmark:
        "results/benchmarks/metrics/mujoco/{method}/{suite}/{scene}.tsv"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=15,
    conda:
        ENV
    script:
        "../scripts/mujoco_metrics.py"


rule recon_metrics:
    input:
        scene="results/methods/{method}/{suite}/{scene}/scene.json",
        gt="results/scenes/{suite}/{scene}/gt/scene.json",
    output:
        "results/metrics/recon/{method}/{suite}/{scene}.json",
    params:
        recon=config["metrics"]["recon"],
        version=V.METRICS,
    log:
        "results/logs/metrics/recon/{method}/{suite}/{scene}.log",
    benchmark:
        "results/benchmarks/metrics/recon/{method}/{suite}/{scene}.tsv"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=15,
    conda:
        ENV
    script:
        "../scripts/recon_metrics.py"


rule alignment_metrics:
    input:
        scene="results/methods/{method}/{suite}/{scene}/scene.json",
        initial="results/scenes/{suite}/{scene}/initial/scene.json",
        image="results/scenes/{suite}/{scene}/reference/image.png",
        segmentation="results/scenes/{suite}/{scene}/reference/segmentation.png",
        camera="results/scenes/{suite}/{scene}/reference/camera.json",
    output:
        "results/metrics/alignment/{method}/{suite}/{scene}.json",
    params:
        alignment=config["metrics"]["alignment"],
        version=V.METRICS,
    log:
        "results/logs/metrics/alignment/{method}/{suite}/{scene}.log",
    benchmark:
        "results/benchmarks/metrics/alignment/{method}/{suite}/{scene}.tsv"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=15,
    conda:
        ENV
    script:
        "../scripts/alignment_metrics.py"
