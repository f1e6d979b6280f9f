# Shared helpers: scene lists, method lookup, paths. Everything a job uses reaches it through params.

import phiscene.versions as V

RESULTS = "results"
CACHE = config["cache_dir"]
ENV = os.path.join(workflow.basedir, "envs/phiscene.yaml")


def scene_ids(suite):
    """Scene ids of a suite: an explicit list, a real-data source's rooms, or scene_000 .. scene_{n-1}."""
    s = config["suites"][suite]
    if "scenes" in s:
        return list(s["scenes"])
    if "source" in s:  # 3D-FRONT test rooms (phiscene.io.front3d), from the source's room list file
        from phiscene.io.front3d import scene_ids as _front3d_scene_ids

        return _front3d_scene_ids(s["source"])
    return [f"scene_{i:03d}" for i in range(s["n_scenes"])]


def scene_index(wildcards):
    ids = scene_ids(wildcards.suite)
    return ids.index(wildcards.scene)


def methods_of_kind(kind):
    return [m for m, spec in config["methods"].items() if spec["kind"] == kind]


#: Method kinds with a rule outside workflow/rules/baselines/ (methods.smk).
BUILTIN_KINDS = ("reference", "phi_scene")
#: Method kinds whose scenes bring their own meshes (their proxies are computed from the method's scene).
OWN_MESH_KINDS = ("external",)


def check_method_kinds():
    """Every configured method's kind must have a rule (built in, or workflow/rules/baselines/<kind>.smk)."""
    import glob as _glob

    known = set(BUILTIN_KINDS) | {
        os.path.splitext(os.path.basename(f))[0]
        for f in _glob.glob(os.path.join(workflow.basedir, "workflow/rules/baselines/*.smk"))
    }
    for name, spec in config["methods"].items():
        if spec["kind"] not in known:
            raise ValueError(
                f"config: methods.{name}.kind: unknown kind {spec['kind']!r}; known: {sorted(known)} "
                f"(add workflow/rules/baselines/{spec['kind']}.smk for a new one)"
            )


def proxies_of(wildcards):
    """Proxies for the simulated metrics of a method's scene."""
    if config["methods"][wildcards.method]["kind"] in OWN_MESH_KINDS:
        return f"results/methods/{wildcards.method}/{wildcards.suite}/{wildcards.scene}/proxies.npz"
    return f"results/proxies/{wildcards.suite}/{wildcards.scene}.npz"


def alternation(names):
    """Regex alternation of names, or a pattern that matches nothing."""
    return "|".join(names) if names else "(?!x)x"


def table_inputs(metric, table, names):
    """Per-name lists of metric files of every scene of the table's suite."""
    suite = config["tables"][table]["suite"]
    return {name: expand(f"results/metrics/{metric}/{name}/{suite}/{{scene}}.json", scene=scene_ids(suite))
            for name in names}


def topology_inputs(wildcards):
    """The initial scene, plus the benchmark's ground-truth graph for the `given` backend."""
    base = f"results/scenes/{wildcards.suite}/{wildcards.scene}"
    inputs = {"scene": f"{base}/initial/scene.json"}
    if wildcards.backend == "given":
        inputs["given"] = f"{base}/gt/topology.json"
    return inputs


wildcard_constraints:
    suite=alternation(list(config["suites"])),
    scene="[A-Za-z0-9_]+",
    backend="[a-z_]+",
