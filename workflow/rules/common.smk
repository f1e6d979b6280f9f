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

        return _rest3d_scene_ids(s["source"]["root"], s["source"].get("variant", "sam3d"))
    if "source" in s and s["source"]["kind"] == "sam3d":  # every run in the source's folder
        from phiscene.io.sam3d import scene_ids as _sam3d_scene_ids

        return _sam3d_scene_ids(s["source"]["root"])
    if "source" in s and s["source"]["kind"] == "placed":  # every scene folder in the source's folder
        from phiscene.io.placed_suite import scene_ids as _placed_scene_ids

        return _placed_scene_ids(s["source"]["root"])
    if "source" in s:  # 3D-FRONT test rooms (phiscene.io.front3d), from the source's room list file
        from phiscene.io.front3d import scene_ids as _front3d_scene_ids

        return _front3d_scene_ids(s["source"])
    return [f"scene_{i:03d}" for i in range(s["n_scenes"])]


def scene_index(wildcards):
    """Position of a job's scene in its suite (the benchmark generator's scene number)."""
    ids = scene_ids(wildcards.suite)
    if wildcards.scene not in ids:
        raise ValueError(
            f"no scene {wildcards.scene!r} in suite {wildcards.suite!r}: its scenes are "
            f"{', '.join(ids[:3])}{' ... ' + ids[-1] if len(ids) > 3 else ''}"
        )
    return ids.index(wildcards.scene)


def benchmark_suites():
    """Suites the embedded benchmark generates (those without a real-data `source`)."""
    return [s for s in config["suites"] if "source" not in config["suites"][s]]


def source_suites(kind):
    """Suites read from a real-data `source` of one kind (front3d: 3D-FRONT; rest3d: REST3D page assets; sam3d: a
    folder of SAM 3D Objects runs; placed: a folder of scenes of per-object meshes placed in one frame)."""
    return [s for s, spec in config["suites"].items() if spec.get("source", {}).get("kind") == kind]


def rest3d_inputs(wildcards):
    """The REST3D files one scene's import reads: a missing checkout fails the DAG naming the missing path."""
    source = config["suites"][wildcards.suite]["source"]
    folder = os.path.join(source["root"], "assets", wildcards.scene, source.get("variant", "sam3d"))
    return {"simulation": os.path.join(folder, "simulation.json")}


def sam3d_inputs(wildcards):
    """The files one SAM 3D Objects run's import reads (its objects' pose.json and meshes, its camera, image, floor
    and masks): a missing run fails the DAG naming the missing path."""
    folder = os.path.join(config["suites"][wildcards.suite]["source"]["root"], wildcards.scene)
    found = sorted(
        glob.glob(os.path.join(folder, "*", "pose.json"))
        + glob.glob(os.path.join(folder, "*", "mesh.*"))
        + glob.glob(os.path.join(folder, "*", "mask.png"))
        + [
            os.path.join(folder, f)
            for f in ("camera.json", "image.png", "segmentation.png", "floor.json")
            if os.path.isfile(os.path.join(folder, f))
        ]
    )
    return found or [os.path.join(folder, "<object id>", "pose.json")]


def placed_inputs(wildcards):
    """The files one scene of a `placed` suite's import reads (its mesh files, placements.json and camera.json): a
    missing scene fails the DAG naming the missing path."""
    from phiscene.io.placed import MESH_SUFFIXES

    folder = os.path.join(config["suites"][wildcards.suite]["source"]["root"], wildcards.scene)
    found = sorted(
        f.path
        for f in (os.scandir(folder) if os.path.isdir(folder) else [])
        if f.is_file()
        and (os.path.splitext(f.name)[1].lower() in MESH_SUFFIXES or f.name in ("placements.json", "camera.json"))
    )
    return found or [os.path.join(folder, "<object>.glb")]


def source_scene_inputs(wildcards):
    """The files one scene of a `sam3d` or `placed` suite's import reads (`sam3d_inputs`, `placed_inputs`)."""
    kind = config["suites"][wildcards.suite]["source"]["kind"]
    return sam3d_inputs(wildcards) if kind == "sam3d" else placed_inputs(wildcards)


def source_has_camera(suite, scene):
    """Whether a scene of a `sam3d` or `placed` suite gives its camera (camera.json: a SAM 3D run's intrinsics, a
    placed scene's eye, target and field of view): its import writes the photo's camera (reference/camera.json)."""
    return os.path.isfile(os.path.join(config["suites"][suite]["source"]["root"], scene, "camera.json"))


def camera_scenes(suite):
    """The scenes of a `sam3d` or `placed` suite that give their camera (`source_has_camera`)."""
    root = config["suites"][suite]["source"]["root"]
    if not os.path.isdir(root):
        return []
    return [s for s in scene_ids(suite) if source_has_camera(suite, s)]


def suite_generator(wildcards):
    """The embedded generator of a benchmark job's suite (`suites.<suite>.generator`, default its name)."""
    return phiscene.config.suite_generator(config, wildcards.suite)


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


#: Method kinds built by their own rules (methods.smk: reference, phi_scene; workflow/rules/baselines/*.smk).
BUILTIN_KINDS = ("reference", "phi_scene")
#: Method kinds whose scenes bring their own meshes (their proxies are computed from the method's scene).
OWN_MESH_KINDS = ("external",)


def registered_baseline_methods():
    """Methods whose kind is a registered baseline (phiscene.baselines.registry): the generic `baseline` rule's."""
    from phiscene.baselines.registry import BASELINES

    return [m for m, spec in config["methods"].items() if spec["kind"] in BASELINES]


def check_method_kinds():
    """Every configured method's kind must have a rule: built in, a registered baseline, or a rule file
    workflow/rules/baselines/<kind>.smk."""
    import glob as _glob

    from phiscene.baselines.registry import BASELINES

    known = (
        set(BUILTIN_KINDS)
        | set(BASELINES)
        | {
            os.path.splitext(os.path.basename(f))[0]
            for f in _glob.glob(os.path.join(workflow.basedir, "workflow/rules/baselines/*.smk"))
        }
    )
    for name, spec in config["methods"].items():
        if spec["kind"] not in known:
            raise ValueError(
                f"config: methods.{name}.kind: unknown kind {spec['kind']!r}; known: {sorted(known)} "
                "(register a baseline in phiscene.baselines.registry for a new one)"
            )


def method_kind(wildcards):
    """The kind of a job's method."""
    return config["methods"][wildcards.method]["kind"]


def external_prediction(wildcards):
    """The prediction folder of a job's external method (its `path` with suite and scene filled in)."""
    return config["methods"][wildcards.method]["path"].format(suite=wildcards.suite, scene=wildcards.scene)


def baseline_inputs(wildcards):
    """The initial scene, plus what the method's registered baseline needs (proxies, its topology graph)."""
    from phiscene.baselines.registry import get_baseline

    base = f"results/scenes/{wildcards.suite}/{wildcards.scene}"
    inputs = {"scene": f"{base}/initial/scene.json"}
    needs = get_baseline(method_kind(wildcards)).needs
    if "proxies" in needs:
        inputs["proxies"] = f"results/proxies/{wildcards.suite}/{wildcards.scene}.npz"
    if "topology" in needs:
        inputs["topology"] = method_topology(wildcards)
    return inputs


def method_scene(method, suite, scene):
    """The scene.json of a method: a reference method's is the benchmark scene itself (no copy job)."""
    spec = config["methods"][method]
    if spec["kind"] == "reference":
        return f"results/scenes/{suite}/{scene}/{spec['source']}/scene.json"
    return f"results/methods/{method}/{suite}/{scene}/scene.json"


def reconstructed_suite(suite):
    """Whether a benchmark suite's initial meshes are reconstructions, not the ground truth's (`degrade.kind:
    foundation`): its ground-truth row then needs proxies of its own meshes."""
    if "source" in config["suites"][suite]:
        return False
    from phiscene.bench.build import with_suite_defaults

    merged = with_suite_defaults(
        phiscene.config.suite_generator(config, suite), phiscene.config.bench_settings(config, suite)
    )
    return (merged.get("degrade") or {}).get("kind", "clean") == "foundation"


def method_proxies(method, suite, scene):
    """Proxies for the simulated metrics of a method's scene: the scene's shared ones (of its initial meshes),
    its own if its scenes bring their own meshes, the ground truth's on a suite whose initial meshes are
    reconstructions."""
    spec = config["methods"][method]
    if spec["kind"] in OWN_MESH_KINDS:
        return f"results/methods/{method}/{suite}/{scene}/proxies.npz"
    if spec["kind"] == "reference" and spec["source"] == "gt" and reconstructed_suite(suite):
        return f"results/proxies/{suite}/{scene}.gt.npz"
    return f"results/proxies/{suite}/{scene}.npz"


def own_proxies(method, suite):
    """Whether a method's metrics on a suite use proxies other than the scene's shared ones."""
    return method_proxies(method, suite, "x") != f"results/proxies/{suite}/x.npz"


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


def phi_scene_inputs(wildcards):
    """A phi_scene-kind job's inputs: initial scene, its method's support graph, proxies, and the photo's camera
    when the suite has one and the faithful method uses it (`faithful.ray`, `faithful.hidden_share`)."""
    base = f"results/scenes/{wildcards.suite}/{wildcards.scene}"
    inputs = {
        "scene": f"{base}/initial/scene.json",
        "topology": method_topology(wildcards),
        "proxies": f"results/proxies/{wildcards.suite}/{wildcards.scene}.npz",
    }
    faithful = method_assembly(wildcards).get("faithful", {})  # config.yaml gives every key
    has_camera = (
        wildcards.suite in benchmark_suites()
        or wildcards.suite in source_suites("rest3d")
        or (
            wildcards.suite in source_suites("sam3d") + source_suites("placed")
            and source_has_camera(wildcards.suite, wildcards.scene)
        )
    )
    if faithful.get("enabled") and (faithful.get("ray") or faithful.get("hidden_share", 0) > 0) and has_camera:
        inputs["camera"] = f"{base}/reference/camera.json"
    return inputs


def method_assembly(wildcards):
    """Assembly settings of a job's phi_scene-kind method: its `assembly` override deep-merged over `assembly`, less
    the faithful settings where faithful grounding is off (phiscene.config.job_assembly)."""
    return phiscene.config.job_assembly(config, wildcards.method)


def baseline_settings(wildcards):
    """`methods.<method>.params` of a job's baseline method (defaults when absent)."""
    return config["methods"][wildcards.method].get("params", {})


def alternation(names):
    """Regex alternation of names, or a pattern that matches nothing."""
    return "|".join(names) if names else "(?!x)x"


def tables_showing(method, suite):
    """The configured tables with metrics files (their kind reads metric sections) that show a method on a suite."""
    return [
        t
        for t, spec in config["tables"].items()
        if table_kind(t).metric_sections() and spec.get("suite") == suite and method in spec.get("methods", [])
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
    from phiscene.metrics.evaluate import check_sections

    return check_sections({s for t in tables_showing(method, suite) for s in table_kind(t).metric_sections()})


def metric_tasks(suite, methods):
    """Per method: its sections, and whether it brings its own proxies (params of a metrics job)."""
    return [
        {
            "method": m,
            "sections": metric_sections(m, suite),
            "own_proxies": own_proxies(m, suite),
            "align": config["methods"][m].get("frame", "shared") == "own",
        }
        for m in methods
    ]


def metric_settings(suite, methods):
    """The settings the methods' metric sections read (a change reruns only the jobs that use it)."""
    from phiscene.metrics.evaluate import section_settings

    names = {n for t in metric_tasks(suite, methods) for n in section_settings(t["sections"])}
    return {n: (config["sim"] if n == "sim" else config["metrics"].get(n, {})) for n in sorted(names)}


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


def table_kind(name):
    """The registered kind (phiscene.table_registry) of table `name`: its `tables.<name>.kind`, default the name."""
    from phiscene.table_registry import kind_of

    return kind_of(name, config["tables"].get(name))


def table_names():
    """Every table the generic `table` job makes. The configured ones, then the registered kinds that need no config
    (those reading the benchmark TSVs: runtime)."""
    from phiscene.table_registry import TABLE_KINDS

    names = list(config["tables"])
    return names + [k for k, kind in TABLE_KINDS.items() if kind.reads == "benchmarks" and k not in names]


def table_available(name):
    """Whether a table's suite has its data here (tables without a suite always are)."""
    suite = config["tables"].get(name, {}).get("suite")
    return suite is None or suite_available(suite)


def table_scenes(name):
    """Scene ids of a table's suite ([] for a table without one)."""
    suite = config["tables"].get(name, {}).get("suite")
    return scene_ids(suite) if suite else []


def table_rows(name):
    """Rows of a table: its configured `methods` or `backends` (by its kind), [] for a kind without rows."""
    key = table_kind(name).rows
    return list(config["tables"][name][key]) if key else []


def table_inputs(table):
    """Per method of a table: the metrics files of every scene of the table's suite."""
    suite = config["tables"][table]["suite"]
    return {m: expand(f"results/metrics/{m}/{suite}/{{scene}}.json", scene=scene_ids(suite)) for m in table_rows(table)}


def table_rule_inputs(wildcards):
    """Inputs of the `table` rule, by what the table's kind reads (phiscene.table_registry.READS)."""
    name = wildcards.table
    kind = table_kind(name)
    if kind.reads == "benchmarks":  # the jobs of the embedded-benchmark tables wrote the TSVs it reads
        return {"tables": [f"results/tables/{t}.csv" for t in benchmark_tables()]}
    suite = config["tables"][name]["suite"]
    scenes = scene_ids(suite)
    if kind.reads == "topology":
        inputs = {b: expand(f"results/topology/{b}/{suite}/{{scene}}.json", scene=scenes) for b in table_rows(name)}
        inputs["gt_topology"] = expand(f"results/scenes/{suite}/{{scene}}/gt/topology.json", scene=scenes)
        return inputs
    inputs = table_inputs(name)
    if kind.logs:
        for m in table_rows(name):
            if config["methods"][m]["kind"] == "phi_scene":
                inputs[f"log_{m}"] = expand(f"results/methods/{m}/{suite}/{{scene}}/assembly.json", scene=scenes)
    return inputs


def table_params(wildcards):
    """What the table script needs besides its inputs: kind, rows, scenes and Markdown heading."""
    from phiscene.table_registry import heading_of

    name = wildcards.table
    return {
        "kind": table_kind(name).name,
        "rows": table_rows(name),
        "scenes": table_scenes(name),
        "heading": heading_of(name, config["tables"].get(name)),
        "benchmarks": "results/benchmarks",
    }


def benchmark_tables():
    """Configured tables on embedded-benchmark suites (no real-data `source`): the runtime table's inputs, so that
    `snakemake results/tables/runtime.csv` never needs real data."""
    return [t for t, spec in config["tables"].items() if "source" not in config["suites"][spec["suite"]]]


#: Notes already printed while the DAG is built (each once).
NOTES_SHOWN = set()


def default_tables():
    """Tables of the default target (`all`). Every configured table whose suite's data are here (a note names the others),
    then the runtime table (which reads the benchmark TSVs of `benchmark_tables()`)."""
    out = []
    for name in config["tables"]:
        if table_available(name):
            out.append(name)
            continue
        suite = config["tables"][name]["suite"]
        root = config["suites"][suite]["source"]["root"]
        note = (
            f"note: results/tables/{name}.csv skipped: the {suite} suite's data are not at {root} "
            "(README, 'Real scenes', says how to get them)"
        )
        if note not in NOTES_SHOWN:
            NOTES_SHOWN.add(note)
            print(note, file=sys.stderr)
    return out + [t for t in table_names() if t not in config["tables"]]


def default_table_files():
    """Files of `default_tables()`: each CSV, and the per-scene CSV of kinds that write one."""
    out = []
    for t in default_tables():
        out.append(f"results/tables/{t}.csv")
        if table_kind(t).scene_rows is not None:
            out.append(f"results/tables/{t}_scenes.csv")
    return out


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


def suite_proxies(wildcards):
    """`proxies` with the suite's `proxies:` override deep-merged over it (phiscene.config)."""
    return phiscene.config.suite_proxies(config, wildcards.suite)


wildcard_constraints:
    suite=alternation(list(config["suites"])),
    scene="[A-Za-z0-9_]+",
    backend="[a-z_]+",
