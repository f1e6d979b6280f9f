# Shared helpers: scene lists, method lookup, paths. Everything a job uses reaches it through params.

import phiscene.versions as V

RESULTS = "results"
CACHE = config["cache_dir"]
ENV = "../../envs/phiscene.yaml"


def scene_ids(suite):
    """Scene ids of a suite: an explicit list, or scene_000 .. scene_{n-1}."""
    s = config["suites"][suite]
    if "scenes" in s:
        return list(s["scenes"])
    return [f"scene_{i:03d}" for i in range(s["n_scenes"])]


def scene_index(wildcards):
    ids = scene_ids(wildcards.suite)
    return ids.index(wildcards.scene)


def methods_of_kind(kind):
    return [m for m, spec in config["methods"].items() if spec["kind"] == kind]


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
