# Shared helpers: scene lists, method lookup, paths. Everything a job uses reaches it through params.

import phiscene.config
import phiscene.versions as V

RESULTS = "results"
CACHE = config["cache_dir"]
ENV = os.path.join(workflow.basedir, "envs/phiscene.yaml")


def scene_ids(suite):
    """Scene ids of a suite: an explicit list, a real-data source's rooms, or scene_000 .. scene_{n-1}."""
    s = config["suites"][suite]
    if "scenes" in s:
        return list(s["scenes"])
    if "source" in s and s["source"]["kind"] == "rest3d":  # every scene of the REST3D checkout
        from phiscene.io.rest3d import scene_ids as _rest3d_scene_ids

        return _rest3d_scene_ids(s["source"]["root"])
    if "source" in s:  # 3D-FRONT test rooms (phiscene.io.front3d), from the source's room list file
        from phiscene.io.front3d import scene_ids as _front3d_scene_ids

        return _front3d_scene_ids(s["source"])
    return [f"scene_{i:03d}" for i in range(s["n_scenes"])]


def scene_index(wildcards):
    """Position of a job's scene in its suite (the benchmark generator's scene number)."""
    ids = scene_ids(wildcards.suite)
    return ids.index(wildcards.scene)


def benchmark_suites():
    """Suites the embedded benchmark generates (those without a real-data `source`)."""
    return [s for s in config["suites"] if "source" not in config["suites"][s]]


def source_suites(kind):
    """Suites read from a real-data `source` of one kind (front3d: 3D-FRONT; rest3d: REST3D page assets)."""
    return [s for s, spec in config["suites"].items() if spec.get("source", {}).get("kind") == kind]


def rest3d_inputs(wildcards):
    """The REST3D files one scene's import reads: a missing checkout fails the DAG naming the missing path."""
    source = config["suites"][wildcards.suite]["source"]
    folder = os.path.join(source["root"], "assets", wildcards.scene, source.get("variant", "sam3d"))
    return {"simulation": os.path.join(folder, "simulation.json")}


def benchmark_settings(wildcards):
    """`benchmark` with the suite's override deep-merged over it, plus `sim` and `proxies` (phiscene.config)."""
    return phiscene.config.bench_settings(config, wildcards.suite)


def suite_source(wildcards):
    """The real-data `source` mapping of a job's suite."""
    return config["suites"][wildcards.suite]["source"]


def topology_settings(wildcards):
    """`topology.<backend>` of a job's backend (defaults when absent)."""
    return config["topology"].get(wildcards.backend, {})


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


def method_scene(method, suite, scene):
    """The scene.json of a method: a reference method's is the benchmark scene itself (no copy job)."""
    spec = config["methods"][method]
    if spec["kind"] == "reference":
        return f"results/scenes/{suite}/{scene}/{spec['source']}/scene.json"
    return f"results/methods/{method}/{suite}/{scene}/scene.json"


def method_proxies(method, suite, scene):
    """Proxies for the simulated metrics of a method's scene: its own if its scenes bring their own meshes."""
    if config["methods"][method]["kind"] in OWN_MESH_KINDS:
        return f"results/methods/{method}/{suite}/{scene}/proxies.npz"
    return f"results/proxies/{suite}/{scene}.npz"


def proxies_of(wildcards):
    """method_proxies of a job's method, suite and scene."""
    return method_proxies(wildcards.method, wildcards.suite, wildcards.scene)


def scene_of(wildcards):
    """method_scene of a job's method, suite and scene."""
    return method_scene(wildcards.method, wildcards.suite, wildcards.scene)


def method_topology(wildcards):
    """The support graph a job's method places by: its `topology` backend's graph of the scene."""
    backend = config["methods"][wildcards.method]["topology"]
    return f"results/topology/{backend}/{wildcards.suite}/{wildcards.scene}.json"


def method_assembly(wildcards):
    """Assembly settings of a job's phi_scene-kind method: its `assembly` override deep-merged over `assembly`."""
    return phiscene.config.method_assembly(config, wildcards.method)


def baseline_settings(wildcards):
    """`methods.<method>.params` of a job's baseline method (defaults when absent)."""
    return config["methods"][wildcards.method].get("params", {})


def alternation(names):
    """Regex alternation of names, or a pattern that matches nothing."""
    return "|".join(names) if names else "(?!x)x"


def tables_showing(method, suite):
    """The tables with metrics files (phiscene.metrics.evaluate.TABLE_SECTIONS) that show a method on a suite."""
    from phiscene.metrics.evaluate import TABLE_SECTIONS

    return [
        t for t in TABLE_SECTIONS if config["tables"][t]["suite"] == suite and method in config["tables"][t]["methods"]
    ]


def metric_groups(suite):
    """Methods with metrics files on a suite, grouped by the tables that show them: {"phys_crosssim": [...], ...}.

    One job per scene computes a group's files, so a table pulls in only the methods it shows, and a change to
    one method reruns only its group's jobs.
    """
    groups = {}
    for m in config["methods"]:
        tables = tables_showing(m, suite)
        if tables:
            groups.setdefault("_".join(tables), []).append(m)
    return groups


def metric_sections(method, suite):
    """Sections of a method's metrics files on a suite: those of every table that shows the method there."""
    from phiscene.metrics.evaluate import TABLE_SECTIONS, check_sections

    return check_sections({s for t in tables_showing(method, suite) for s in TABLE_SECTIONS[t]})


def metric_tasks(suite, methods):
    """Per method: its sections, and whether it brings its own proxies (params of a metrics job)."""
    return [
        {
            "method": m,
            "sections": metric_sections(m, suite),
            "own_proxies": config["methods"][m]["kind"] in OWN_MESH_KINDS,
            "align": config["methods"][m].get("frame", "shared") == "own",
        }
        for m in methods
    ]


def metric_settings(suite, methods):
    """The settings the methods' metric sections read (a change reruns only the jobs that use it)."""
    from phiscene.metrics.evaluate import SECTION_SETTINGS

    names = {n for t in metric_tasks(suite, methods) for s in t["sections"] for n in SECTION_SETTINGS[s]}
    return {n: (config["sim"] if n == "sim" else config["metrics"][n]) for n in sorted(names)}


def metrics_inputs(suite, methods, scene):
    """The methods' scenes, plus what their metric sections read (phiscene.metrics.evaluate.required_inputs)."""
    from phiscene.metrics.evaluate import required_inputs

    base = f"results/scenes/{suite}/{scene}"
    inputs, need = {}, set()
    for t in metric_tasks(suite, methods):
        m = t["method"]
        inputs[f"scene_{m}"] = method_scene(m, suite, scene)
        wanted = set(required_inputs(t["sections"]))
        if "proxies" in wanted and t["own_proxies"]:
            inputs[f"proxies_{m}"] = method_proxies(m, suite, scene)
            wanted.discard("proxies")
        need |= wanted
    if "proxies" in need:
        inputs["proxies"] = f"results/proxies/{suite}/{scene}.npz"
    if "gt" in need:
        inputs["gt"] = f"{base}/gt/scene.json"
    if "initial" in need:
        inputs["initial"] = f"{base}/initial/scene.json"
    if "reference_dir" in need:
        inputs.update(
            image=f"{base}/reference/image.png",
            segmentation=f"{base}/reference/segmentation.png",
            camera=f"{base}/reference/camera.json",
        )
    return inputs


def table_inputs(table):
    """Per method of a table: the metrics files of every scene of the table's suite."""
    suite = config["tables"][table]["suite"]
    return {
        m: expand(f"results/metrics/{m}/{suite}/{{scene}}.json", scene=scene_ids(suite))
        for m in config["tables"][table]["methods"]
    }


def topology_table_inputs(wildcards):
    """Per backend the predicted support graphs of the topology table's suite, and the ground-truth graphs."""
    suite = config["tables"]["topology"]["suite"]
    scenes = scene_ids(suite)
    inputs = {
        b: expand(f"results/topology/{b}/{suite}/{{scene}}.json", scene=scenes)
        for b in config["tables"]["topology"]["backends"]
    }
    inputs["gt_topology"] = expand(f"results/scenes/{suite}/{{scene}}/gt/topology.json", scene=scenes)
    return inputs


def topology_inputs(wildcards):
    """The initial scene, plus the benchmark's ground-truth graph for the `given` backend."""
    base = f"results/scenes/{wildcards.suite}/{wildcards.scene}"
    inputs = {"scene": f"{base}/initial/scene.json"}
    if wildcards.backend == "given":
        inputs["given"] = f"{base}/gt/topology.json"
    return inputs


def suite_available(suite):
    """Whether a suite's data are here: real-data suites need their local copy (`source.root`)."""
    source = config["suites"][suite].get("source")
    return source is None or os.path.isdir(os.path.join(source["root"], "assets" if source["kind"] == "rest3d" else ""))


def real_table_scenes(wildcards=None):
    """Scene ids of the real table's suite."""
    return scene_ids(config["tables"]["real"]["suite"])


def real_table_inputs(wildcards):
    """Metrics files of every method of the real table, plus the assembly logs of its grounding methods."""
    if "real" not in config["tables"]:
        raise ValueError("config: tables.real is not configured (suite and methods of the real-scene table)")
    inputs = table_inputs("real")
    suite = config["tables"]["real"]["suite"]
    for m in config["tables"]["real"]["methods"]:
        if config["methods"][m]["kind"] == "phi_scene":
            inputs[f"log_{m}"] = expand(f"results/methods/{m}/{suite}/{{scene}}/assembly.json", scene=scene_ids(suite))
    return inputs


def optional_tables():
    """Tables the default target adds: the real table when its suite's data are here (else a note)."""
    if "real" not in config["tables"]:
        return []
    suite = config["tables"]["real"]["suite"]
    if suite_available(suite):
        return ["results/tables/real.csv"]
    root = config["suites"][suite]["source"]["root"]
    print(
        f"note: results/tables/real.csv skipped: the {suite} suite's data are not at {root} "
        "(README, 'Real scenes', says how to get them)",
        file=sys.stderr,
    )
    return []


def suite_proxies(wildcards):
    """`proxies` with the suite's `proxies:` override deep-merged over it (phiscene.config)."""
    return phiscene.config.deep_merge(config["proxies"], config["suites"][wildcards.suite].get("proxies", {}))


wildcard_constraints:
    suite=alternation(list(config["suites"])),
    scene="[A-Za-z0-9_]+",
    backend="[a-z_]+",
