# The embedded benchmark: ground truth by simulation, degraded initial scene, reference renders.


rule benchmark_scene:
    output:
        gt="results/scenes/{suite}/{scene}/gt/scene.json",
        gt_topology="results/scenes/{suite}/{scene}/gt/topology.json",
        initial="results/scenes/{suite}/{scene}/initial/scene.json",
        image="results/scenes/{suite}/{scene}/reference/image.png",
        segmentation="results/scenes/{suite}/{scene}/reference/segmentation.png",
        camera="results/scenes/{suite}/{scene}/reference/camera.json",
    wildcard_constraints:
        suite=alternation(benchmark_suites()),
    params:
        index=scene_index,
        bench=benchmark_settings,
        cache_dir=CACHE,
        version=V.BENCHMARK,
    log:
        "results/logs/benchmark/{suite}/{scene}.log",
    benchmark:
        "results/benchmarks/benchmark/{suite}/{scene}.tsv"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=30,
    conda:
        ENV
    script:
        "../scripts/benchmark_scene.py"


rule front3d_scene:
    # a suite with `source: {kind: front3d, root: ...}`: one 3D-FRONT test room in MIDI-3D's layout (phiscene.io.front3d)
    output:
        gt="results/scenes/{suite}/{scene}/gt/scene.json",
        gt_topology="results/scenes/{suite}/{scene}/gt/topology.json",
        initial="results/scenes/{suite}/{scene}/initial/scene.json",
        image="results/scenes/{suite}/{scene}/reference/image.png",
        segmentation="results/scenes/{suite}/{scene}/reference/segmentation.png",
    wildcard_constraints:
        suite=alternation(source_suites("front3d")),
    params:
        source=suite_source,
        version=V.FRONT3D,
    log:
        "results/logs/benchmark/{suite}/{scene}.log",
    benchmark:
        "results/benchmarks/benchmark/{suite}/{scene}.tsv"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=30,
    conda:
        ENV
    script:
        "../scripts/front3d_scene.py"


rule rest3d_scene:
    # a suite with `source: {kind: rest3d, root: ...}`: one scene of the REST3D page assets, levelled (phiscene.io.rest3d)
    input:
        unpack(rest3d_inputs),
    output:
        initial="results/scenes/{suite}/{scene}/initial/scene.json",
        camera="results/scenes/{suite}/{scene}/reference/camera.json",
        record="results/scenes/{suite}/{scene}/import.json",
    wildcard_constraints:
        suite=alternation(source_suites("rest3d")),
    params:
        source=suite_source,
        version=V.IMPORT,
    log:
        "results/logs/benchmark/{suite}/{scene}.log",
    benchmark:
        "results/benchmarks/benchmark/{suite}/{scene}.tsv"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=30,
    conda:
        ENV
    script:
        "../scripts/rest3d_scene.py"
