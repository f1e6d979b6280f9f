# Simulation-ready outputs (phiscene.io.export, phiscene.demo): `snakemake -j2 exports`.
#   results/export/{method}/{suite}/{scene}/   scene.glb, scene.xml (MJCF), scene.usda (OpenUSD + UsdPhysics),
#                                              scene_urdf.json + urdf/ + meshes/,
#                                              support_graph.json, export.json, roundtrip.json
#   results/demo/{suite}/{scene}.gif (+ .json) a ball thrown into the exported scene of export.demo_method
# `rule all` builds the demos of the first export.report_demos scenes of each suite (the report shows them).


include: "export_common.smk"


rule export_scene:
    input:
        scene=scene_of,
        proxies=proxies_of,
        topology=export_topology,
    output:
        glb="results/export/{method}/{suite}/{scene}/scene.glb",
        mjcf="results/export/{method}/{suite}/{scene}/scene.xml",
        usd="results/export/{method}/{suite}/{scene}/scene.usda",
        urdf="results/export/{method}/{suite}/{scene}/scene_urdf.json",
        graph="results/export/{method}/{suite}/{scene}/support_graph.json",
        roundtrip="results/export/{method}/{suite}/{scene}/roundtrip.json",
        manifest="results/export/{method}/{suite}/{scene}/export.json",
    params:
        sim=config["sim"],
        mujoco=config["metrics"]["mujoco"],
        physical=config["metrics"]["physical"],
        cache_dir=CACHE,
        version=EXPORT_VERSION,
    log:
        "results/logs/export/{method}/{suite}/{scene}.log",
    benchmark:
        "results/benchmarks/export/{method}/{suite}/{scene}.tsv"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=15,
    conda:
        ENV
    script:
        "../scripts/export_scene.py"


rule demo:
    input:
        urdf=f"results/export/{DEMO_METHOD}/{{suite}}/{{scene}}/scene_urdf.json",
    output:
        gif="results/demo/{suite}/{scene}.gif",
        summary="results/demo/{suite}/{scene}.json",
    params:
        demo=EXPORT.get("demo", {}),
        render=config["benchmark"].get("render", {}),
        version=EXPORT_VERSION,
    log:
        "results/logs/demo/{suite}/{scene}.log",
    benchmark:
        "results/benchmarks/demo/{suite}/{scene}.tsv"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=15,
    conda:
        ENV
    script:
        "../scripts/demo.py"


rule exports:
    input:
        [
            f"results/export/{m}/{s}/{scene}/export.json"
            for m in EXPORT_METHODS
            for s in EXPORT_SUITES
            for scene in scene_ids(s)
        ],
        [f"results/demo/{s}/{scene}.gif" for s in EXPORT_SUITES for scene in scene_ids(s)],
