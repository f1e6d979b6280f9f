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
        generator=suite_generator,
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


# A suite with `source: {kind: sam3d, root: ...}`: one SAM 3D Objects run (one folder of <object id>/pose.json + mesh)
# per scene (phiscene.io.sam3d); with `source: {kind: placed, root: ...}`: one folder of per-object meshes placed in
# one frame per scene (phiscene.io.placed_suite). Each is levelled and its walls estimated. A scene with camera.json
# also gives the photo's camera; one rule per suite and case, since a rule's outputs are fixed.
# (`script:` takes no loop variable: a rule's script path is read when the job runs, after the loop has ended)
for _kind in ("sam3d", "placed"):
    for _suite in [s for s in source_suites(_kind) if suite_available(s)]:
        _cameras = camera_scenes(_suite)
        for _with_camera, _scenes in ((True, _cameras), (False, [s for s in scene_ids(_suite) if s not in _cameras])):
            if not _scenes:
                continue

            rule:
                name:
                    f"{_kind}_scene_{_suite}" + ("_camera" if _with_camera else "")
                input:
                    source_scene_inputs,
                output:
                    **{
                        "initial": "results/scenes/{suite}/{scene}/initial/scene.json",
                        "record": "results/scenes/{suite}/{scene}/import.json",
                        **({"camera": "results/scenes/{suite}/{scene}/reference/camera.json"} if _with_camera else {}),
                    },
                wildcard_constraints:
                    suite=_suite,
                    scene=alternation(_scenes),
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
                    "../scripts/source_scene.py"
