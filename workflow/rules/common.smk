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


wildcard_constraints:
    suite=alternation(list(config["suites"])),
    scene="[A-Za-z0-9_]+",
    backend="[a-z_]+",
