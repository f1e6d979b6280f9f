# Settings and helpers of workflow/rules/export.smk (kept apart: the linter wants rules and functions in separate files).

#: Bump after a behaviour change of phiscene.io.export or phiscene.demo (reruns exactly these jobs).
EXPORT_VERSION = 3
EXPORT = config.get("export", {})
EXPORT_METHODS = EXPORT.get("methods", ["phi_scene"])
EXPORT_SUITES = EXPORT.get("suites", [s for s in ["contact"] if s in config["suites"]])
DEMO_METHOD = EXPORT.get("demo_method", "phi_scene")
for _m in EXPORT_METHODS + [DEMO_METHOD]:
    if _m not in config["methods"]:
        raise ValueError(f"config: export: unknown method {_m!r}; known: {sorted(config['methods'])}")
for _s in EXPORT_SUITES:
    if _s not in config["suites"]:
        raise ValueError(f"config: export.suites: unknown suite {_s!r}; known: {sorted(config['suites'])}")


def export_topology(wildcards):
    """The support graph exported beside a scene: its method's topology backend, else the geometric one."""
    backend = config["methods"][wildcards.method].get("topology", "geometric")
    return f"results/topology/{backend}/{wildcards.suite}/{wildcards.scene}.json"


def demo_scenes():
    """(suite, scene) pairs whose demo GIF the default target and the report show (first report_demos per suite)."""
    n = int(EXPORT.get("report_demos", 3))
    return [(suite, scene) for suite in EXPORT_SUITES for scene in scene_ids(suite)[:n]]
