# External predictions (SAM 3D Objects, MIDI, any method): one folder per scene imported as a method row.
# config: methods.<name>: {kind: external, path: "predictions/<name>/{suite}/{scene}"} (meshes, poses.json or a GLB).


rule baseline_external:
    input:
        initial="results/scenes/{suite}/{scene}/initial/scene.json",
        prediction=external_prediction,
    output:
        scene="results/methods/{method}/{suite}/{scene}/scene.json",
        log_json="results/methods/{method}/{suite}/{scene}/import.json",
    wildcard_constraints:
        method=alternation(methods_of_kind("external")),
    params:
        settings=baseline_settings,
        version=V.GROUND,
    log:
        "results/logs/methods/{method}/{suite}/{scene}.log",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=15,
    conda:
        ENV
    script:
        "../../scripts/external.py"


rule method_proxies:
    # methods that bring their own meshes need proxies of those meshes for the simulated metrics
    input:
        scene="results/methods/{method}/{suite}/{scene}/scene.json",
    output:
        "results/methods/{method}/{suite}/{scene}/proxies.npz",
    wildcard_constraints:
        method=alternation(methods_of_kind("external")),
    params:
        proxies=suite_proxies,
        cache_dir=CACHE,
        version=V.PROXIES,
    log:
        "results/logs/proxies/{method}/{suite}/{scene}.log",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=30,
    conda:
        ENV
    script:
        "../../scripts/proxies.py"
