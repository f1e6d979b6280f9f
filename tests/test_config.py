"""The workflow configuration: deep-merged overrides, one-line key checks while the DAG is built, schema in sync."""

import copy
import json
import os
import subprocess
import sys
import typing
from dataclasses import fields
from pathlib import Path

import jsonschema
import pytest
import yaml

from phiscene.config import (
    SECTIONS,
    SOURCE_PARAMS,
    ConfigError,
    check_config,
    deep_merge,
    job_assembly,
    load_class,
    method_assembly,
    method_params,
    scaling_settings,
    schema_sections,
    suite_generator,
    suite_proxies,
)
from phiscene.io.source import SourceParams
from phiscene.params import Params, nested_params
from phiscene.topology import get_backend

ROOT = Path(__file__).resolve().parents[1]
CONFIG = yaml.safe_load((ROOT / "config/config.yaml").read_text())
SCHEMA = yaml.safe_load((ROOT / "config/schema.yaml").read_text())
BUILTIN_BACKENDS = ("geometric", "height", "given", "mllm")


def dry_run(tmp_path, overrides: dict):
    """`snakemake -n` of the phys table with `overrides` as a --configfile, in an empty folder."""
    cfg = tmp_path / "override.yaml"
    cfg.write_text(yaml.safe_dump(overrides))
    env = {**os.environ, "PYTHONHASHSEED": "0"}
    cmd = [sys.executable, "-m", "snakemake", "-s", str(ROOT / "Snakefile"), "--directory", str(tmp_path / "run"),
           "-n", "-j1", "--configfile", str(cfg), "--", "results/tables/phys.csv"]
    res = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    return res.returncode, res.stdout + res.stderr


# ---------------------------------------------------------------------------------------------------- merging


def test_deep_merge_merges_every_level_and_copies():
    base = {"a": 1, "p": {"x": 1, "y": {"u": 1, "v": 2}}, "l": [1, 2]}
    over = {"p": {"y": {"v": 3}}, "l": [9], "new": {"k": 0}}
    merged = deep_merge(base, over)
    assert merged == {"a": 1, "p": {"x": 1, "y": {"u": 1, "v": 3}}, "l": [9], "new": {"k": 0}}
    merged["p"]["y"]["u"] = 99
    assert base["p"]["y"]["u"] == 1 and over == {"p": {"y": {"v": 3}}, "l": [9], "new": {"k": 0}}
    assert deep_merge(base, None) == base and deep_merge(None, over) == over


def _shifted(section: dict) -> dict:
    """Every number and choice of a config section changed (ints + 1, floats halved or, at 0, set to 0.25, choices
    swapped), so no value equals a dataclass default."""
    swap = {"adam": "steepest"}
    out = {}
    for key, value in section.items():
        if isinstance(value, dict):
            out[key] = _shifted(value)
        elif isinstance(value, str) and value in swap:
            out[key] = swap[value]
        elif isinstance(value, bool) or not isinstance(value, (int, float)):
            out[key] = value
        else:
            out[key] = value + 1 if isinstance(value, int) else (value * 0.5 if value else 0.25)
    return out


@pytest.mark.parametrize("shift", [False, True], ids=["config.yaml", "shifted"])
def test_method_override_of_one_nested_key_keeps_the_other_keys_of_config_yaml(shift):
    from phiscene.assembly.assemble import AssemblyParams

    config = copy.deepcopy(CONFIG)
    if shift:  # a config.yaml whose values all differ from the dataclass defaults: a fallback would show
        config["assembly"] = _shifted(config["assembly"])
    base = copy.deepcopy(config["assembly"])
    config["methods"]["tight"] = {"kind": "phi_scene", "topology": "geometric",
                                  "assembly": {"penetration_params": {"eps": 0.01}, "settle_params": {"window": 7}}}
    check_config(config, schema_sections(ROOT / "config/schema.yaml"))
    p = AssemblyParams.from_dict(method_assembly(config, "tight"))
    defaults = AssemblyParams()
    assert p.penetration_params.eps == 0.01 and p.settle_params.window == 7
    for name, override in (("penetration_params", "eps"), ("settle_params", "window")):
        for key, value in base[name].items():
            if key != override:
                assert getattr(getattr(p, name), key) == value, (name, key)
                if shift:
                    assert getattr(getattr(defaults, name), key) != value, (name, key)
    assert p.penetration == base["penetration"] and p.settle == base["settle"]


def test_job_assembly_leaves_out_faithful_settings_of_methods_without_faithful_grounding():
    """A faithful setting changed in the global ``assembly`` changes the params of the methods that ground faithfully
    only (Snakemake reruns a job whose params change): ``phi_scene_paper``'s stay those of the paper's loop."""
    from phiscene.assembly.assemble import AssemblyParams

    changed = copy.deepcopy(CONFIG)
    changed["assembly"]["faithful"]["carry_margin"] = CONFIG["assembly"]["faithful"]["carry_margin"] + 0.25
    check_config(changed, schema_sections(ROOT / "config/schema.yaml"))
    assert job_assembly(changed, "phi_scene_paper") == job_assembly(CONFIG, "phi_scene_paper")
    assert job_assembly(CONFIG, "phi_scene_paper")["faithful"] == {"enabled": False}
    assert job_assembly(changed, "phi_scene")["faithful"]["carry_margin"] == \
        CONFIG["assembly"]["faithful"]["carry_margin"] + 0.25
    assert job_assembly(CONFIG, "phi_scene") == method_assembly(CONFIG, "phi_scene")
    # what the paper's loop reads is the same: every setting but the faithful ones
    paper = AssemblyParams.from_dict(job_assembly(CONFIG, "phi_scene_paper"))
    full = AssemblyParams.from_dict(method_assembly(CONFIG, "phi_scene_paper"))
    assert not paper.faithful.enabled and not full.faithful.enabled
    assert {k: v for k, v in paper.to_dict().items() if k != "faithful"} == \
        {k: v for k, v in full.to_dict().items() if k != "faithful"}


@pytest.mark.workflow
def test_grounding_job_receives_the_deep_merged_override(tmp_path):
    """End to end: one tiny scene grounded by a method overriding one nested key; its assembly log's params."""
    overrides = {"suites": {"contact": {"n_scenes": 1}}, "proxies": {"backend": "convex"},
                 "benchmark": {"n_objects": [2, 2], "render": {"width": 64, "height": 48}},
                 "assembly": {"penetration_params": {"n_active": 256, "n_context": 256}},
                 "methods": {"tight": {"kind": "phi_scene", "topology": "height",
                                       "assembly": {"penetration_params": {"eps": 0.004}}}}}
    cfg = tmp_path / "override.yaml"
    cfg.write_text(yaml.safe_dump(overrides))
    target = "results/methods/tight/contact/scene_000/assembly.json"
    cmd = [sys.executable, "-m", "snakemake", "-s", str(ROOT / "Snakefile"), "--directory", str(tmp_path / "run"),
           "-j2", "--configfile", str(cfg), "--", target]
    res = subprocess.run(cmd, cwd=ROOT, env={**os.environ, "PYTHONHASHSEED": "0"}, capture_output=True, text=True,
                         timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    got = json.loads((tmp_path / "run" / target).read_text())["params"]
    want_pen = {**CONFIG["assembly"]["penetration_params"], "n_active": 256, "n_context": 256, "eps": 0.004}
    assert {k: got["penetration_params"][k] for k in want_pen} == want_pen
    assert {k: got["settle_params"][k] for k in CONFIG["assembly"]["settle_params"]} == \
        CONFIG["assembly"]["settle_params"]


@pytest.mark.workflow
def test_a_suite_of_another_name_built_by_a_generator_gets_its_scenes(tmp_path):
    """`suites.<name>.generator`: a suite named otherwise, built by the contact generator with the same seed, holds
    the contact suite's scene to the byte (ground truth, meshes and initial scene), beside it in the same results/."""
    overrides = {"suites": {"contact": {"n_scenes": 1}, "contact_b": {"generator": "contact", "n_scenes": 1}},
                 "proxies": {"backend": "convex"},
                 "benchmark": {"n_objects": [2, 2], "render": {"width": 64, "height": 48}}}
    cfg = tmp_path / "override.yaml"
    cfg.write_text(yaml.safe_dump(overrides))
    targets = [f"results/scenes/{s}/scene_000/initial/scene.json" for s in ("contact", "contact_b")]
    cmd = [sys.executable, "-m", "snakemake", "-s", str(ROOT / "Snakefile"), "--directory", str(tmp_path / "run"),
           "-j2", "--configfile", str(cfg), "--", *targets]
    res = subprocess.run(cmd, cwd=ROOT, env={**os.environ, "PYTHONHASHSEED": "0"}, capture_output=True, text=True,
                         timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    a, b = (tmp_path / "run/results/scenes" / s / "scene_000" for s in ("contact", "contact_b"))
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file() and p.suffix in (".json", ".glb", ".obj"))
    assert any(f.parts[0] == "meshes" for f in files) and Path("gt/scene.json") in files
    for f in files:
        assert (a / f).read_bytes() == (b / f).read_bytes(), f


def test_a_suite_names_its_generator_and_an_unknown_one_is_refused():
    config = copy.deepcopy(CONFIG)
    config["suites"]["foo"] = {"n_scenes": 2}
    with pytest.raises(ConfigError, match=r"^config: suites.foo: no embedded benchmark generator 'foo' \(known: "
                                          r"clutter, contact, rooms\); a suite of another name says which builds it"):
        check_config(config)
    config["suites"]["foo"] = {"n_scenes": 2, "generator": "room"}
    with pytest.raises(ConfigError, match=r"^config: suites.foo: no embedded benchmark generator 'room' \(known: "):
        check_config(config)
    config["suites"]["foo"] = {"generator": "rooms", "source": {"kind": "front3d", "root": "x"}}
    with pytest.raises(ConfigError, match=r"^config: suites.foo: `generator` and `source` exclude each other"):
        check_config(config)
    config["suites"]["foo"] = {"n_scenes": 2, "generator": "rooms"}
    check_config(config)
    assert suite_generator(config, "foo") == "rooms" and suite_generator(config, "contact") == "contact"


@pytest.mark.parametrize("override", ["heldout", "real_more", "rest3d_baselines"])
def test_the_override_configs_pass_schema_and_classes(override):
    config = deep_merge(CONFIG, yaml.safe_load((ROOT / f"config/{override}.yaml").read_text()))
    check_config(config)
    jsonschema.validate(config, SCHEMA)
    if override == "heldout":
        assert {suite_generator(config, s) for s in ("contact_f", "rooms_f")} == {"contact", "rooms"}


def test_a_suite_takes_a_named_proxy_profile_then_its_own_override():
    """`proxies`, then `proxy_profiles.<name>`, then the suite's `proxies`, each deep-merged over the one before."""
    config = copy.deepcopy(CONFIG)
    config["proxies"] = {"max_hulls": 16, "seed": 0, "threshold": 0.08}
    config["proxy_profiles"]["light"] = {"max_hulls": 8, "mcts_iterations": 10}
    config["suites"] |= {"a": {"n_scenes": 1, "generator": "contact", "proxy_profile": "light",
                              "proxies": {"mcts_iterations": 5}},
                        "b": {"n_scenes": 1, "generator": "contact", "proxy_profile": "light"},
                        "c": {"n_scenes": 1, "generator": "contact"}}
    check_config(config)
    jsonschema.validate(config, SCHEMA)
    assert suite_proxies(config, "a") == {"max_hulls": 8, "seed": 0, "threshold": 0.08, "mcts_iterations": 5}
    assert suite_proxies(config, "b") == {"max_hulls": 8, "seed": 0, "threshold": 0.08, "mcts_iterations": 10}
    assert suite_proxies(config, "c") == suite_proxies(config) == config["proxies"]
    assert config["proxy_profiles"]["light"] == {"max_hulls": 8, "mcts_iterations": 10}  # nothing modified

    config["suites"]["b"]["proxy_profile"] = "lite"
    with pytest.raises(ConfigError, match=r"^config: suites.b.proxy_profile: no proxy profile 'lite' \(known: light, "
                                          r"reconstruction\)$"):
        check_config(config)
    config["suites"]["b"]["proxy_profile"] = "light"
    config["proxy_profiles"]["light"]["max_hull"] = 8
    with pytest.raises(ConfigError, match=r"^config: proxy_profiles.light: unknown key 'max_hull' \(known: "):
        check_config(config)
    with pytest.raises(jsonschema.ValidationError):  # the schema says the same
        jsonschema.validate(config, SCHEMA)
    with pytest.raises(ConfigError, match=r"^config: suites.a.proxy_profile: no proxy profile 'light' \(known: none"):
        suite_proxies({"proxies": {}, "suites": {"a": {"proxy_profile": "light"}}}, "a")


def test_the_shipped_reconstruction_suites_share_one_proxy_profile():
    """Every suite of reconstructed meshes in the shipped configs (real data, or built with the foundation-model
    degradation) gets its proxies from one named profile rather than a copy of its settings."""
    for override in (None, "heldout", "real_more", "rest3d_baselines"):
        config = CONFIG if override is None else deep_merge(
            CONFIG, yaml.safe_load((ROOT / f"config/{override}.yaml").read_text()))
        for name, spec in config["suites"].items():
            reconstructed = "source" in spec and spec["source"]["kind"] != "front3d" or \
                (spec.get("benchmark") or {}).get("degrade", {}).get("kind") == "foundation"
            if reconstructed:
                assert spec.get("proxy_profile") == "reconstruction" and "proxies" not in spec, (override, name)
                assert suite_proxies(config, name) == deep_merge(config["proxies"],
                                                                 config["proxy_profiles"]["reconstruction"])


# ---------------------------------------------------------------------------------------------------- checks


@pytest.mark.parametrize("edit, path, key", [
    (lambda c: c["assembly"]["penetration_params"].update(epsilon=0.01), "assembly.penetration_params", "epsilon"),
    (lambda c: c["methods"]["seq_sdf_only"].update(assembly={"settle_params": {"windw": 5}}),
     "methods.seq_sdf_only.assembly.settle_params", "windw"),
    (lambda c: c["benchmark"]["degrade"].update(sigma=1.0), "benchmark.degrade", "sigma"),
    (lambda c: c["suites"]["contact"].update(benchmark={"gt": {"settle_second": 1}}), "suites.contact.benchmark.gt",
     "settle_second"),
    (lambda c: c["topology"]["geometric"].update(gap=0.1), "topology.geometric", "gap"),
    (lambda c: c["metrics"]["mujoco"].update(solver="cg"), "metrics.mujoco", "solver"),
    (lambda c: c["export"]["demo"].update(speeed=1), "export.demo", "speeed"),
    (lambda c: c["methods"]["joint_sdf_sim"].update(params={"sdf": {"grid": {"res": 8}}}),
     "methods.joint_sdf_sim.params.sdf.grid", "res"),
    (lambda c: c["suites"].update(front={"source": {"kind": "front3d", "root": "x", "rooms": "r.json"}}),
     "suites.front.source", "rooms"),
])
def test_unknown_key_is_named_with_its_path(edit, path, key):
    config = copy.deepcopy(CONFIG)
    edit(config)
    with pytest.raises(ConfigError) as err:
        check_config(config)
    msg = str(err.value)
    assert msg.startswith(f"config: {path}: unknown key '{key}' (known: ") and "\n" not in msg, msg


def test_value_rules_of_the_classes_run_too():
    config = copy.deepcopy(CONFIG)
    config["benchmark"]["n_objects"] = [5, 2]
    with pytest.raises(ConfigError, match=r"^config: benchmark: .*n_objects"):
        check_config(config)
    config = copy.deepcopy(CONFIG)
    config["topology"]["voxel"] = {}
    with pytest.raises(ConfigError, match=r"^config: topology: unknown backend 'voxel'"):
        check_config(config)
    config = copy.deepcopy(CONFIG)
    config["methods"]["phi_scene"]["assembly"]["faithful"]["carry_sideways"] = "never"
    with pytest.raises(ConfigError, match=r"^config: methods.phi_scene.assembly.faithful: .*carry_sideways must be one "
                                          r"of always, off_support, got 'never'"):
        check_config(config)
    config = copy.deepcopy(CONFIG)
    config["suites"]["real"]["proxies"] = {"refine_max_hulls": -1}
    with pytest.raises(ConfigError, match=r"^config: suites.real.proxies: .*refine_max_hulls must be >= 0"):
        check_config(config)
    with pytest.raises(jsonschema.ValidationError):  # the schema says the same
        jsonschema.validate(config, SCHEMA)


def test_unknown_top_level_section_rejected():
    sections = schema_sections(ROOT / "config/schema.yaml")
    check_config(CONFIG, sections)
    config = {**copy.deepcopy(CONFIG), "assemby": {"settle": False}}
    with pytest.raises(ConfigError, match=r"^config: unknown section 'assemby' \(known: .*assembly"):
        check_config(config, sections)
    with pytest.raises(jsonschema.ValidationError):  # the schema says the same
        jsonschema.validate(config, SCHEMA)


def test_dry_run_accepts_the_default_config_and_rejects_a_misspelled_nested_key(tmp_path):
    rc, out = dry_run(tmp_path, {"suites": {"contact": {"n_scenes": 1}}})
    assert rc == 0 and "metrics_contact_phys_crosssim" in out, out[-3000:]
    rc, out = dry_run(tmp_path, {"assembly": {"penetration_params": {"epsilon": 0.01}}})
    assert rc != 0
    assert "config: assembly.penetration_params: unknown key 'epsilon' (known: " in out, out[-3000:]
    assert "Traceback" not in out and not (tmp_path / "run/results").exists()


def test_dry_run_rejects_a_misspelled_key_of_a_method_override_and_an_unknown_section(tmp_path):
    rc, out = dry_run(tmp_path, {"methods": {"phi_scene": {"assembly": {"settle_params": {"max_frame": 9}}}}})
    assert rc != 0 and "config: methods.phi_scene.assembly.settle_params: unknown key 'max_frame'" in out, out[-3000:]
    rc, out = dry_run(tmp_path, {"metric": {"physical": {"samples": 64}}})
    assert rc != 0 and "config: unknown section 'metric'" in out, out[-3000:]


# ---------------------------------------------------------------------------------------------------- schema


def _resolve(node: dict) -> dict:
    ref = node.get("$ref")
    if ref is None:
        return node
    assert ref.startswith("#/$defs/"), ref
    return SCHEMA["$defs"][ref.removeprefix("#/$defs/")]


def _json_types(annotation) -> set[str]:
    """JSON types a field annotation allows (independent of the schema file)."""
    if isinstance(annotation, str):
        annotation = eval(annotation, vars(typing) | {"tuple": tuple})  # noqa: S307  (dataclass annotations)
    names = {int: "integer", float: "number", bool: "boolean", str: "string", tuple: "array", type(None): "null"}
    args = typing.get_args(annotation) if typing.get_origin(annotation) in (typing.Union, type(int | None)) else ()
    if args:
        return set().union(*(_json_types(a) for a in args))
    origin = typing.get_origin(annotation) or annotation
    return {names[origin]}


def _classes() -> dict[str, type]:
    """Every parameter class a config section is parsed with, and their nested ones, by name."""
    roots = [load_class(s) for s in [*SECTIONS.values(), *SOURCE_PARAMS.values()]] + list(method_params().values())
    roots += [get_backend(b).params_cls for b in BUILTIN_BACKENDS]
    out = {}

    def add(cls):
        out[cls.__name__] = cls
        for sub in nested_params(cls).values():
            add(sub)

    for cls in roots:
        add(cls)
    return out


@pytest.mark.parametrize("name", sorted(_classes()))
def test_schema_lists_exactly_the_fields_of_each_parameter_class(name):
    cls = _classes()[name]
    entry = SCHEMA["$defs"][name]
    assert entry["additionalProperties"] is False and entry["type"] == "object"
    assert list(entry["properties"]) == [f.name for f in fields(cls)]
    nested = nested_params(cls)
    for f in fields(cls):
        prop = entry["properties"][f.name]
        if f.name in nested:
            assert prop == {"$ref": f"#/$defs/{nested[f.name].__name__}"}, f.name
            continue
        allowed = _json_types(f.type)
        if "enum" in prop:
            assert {_json_types(type(v)).pop() for v in prop["enum"]} <= allowed, f.name
        else:
            declared = {prop["type"]} if isinstance(prop["type"], str) else set(prop["type"])
            assert declared == allowed or (allowed == {"number"} and declared == {"integer"}), (f.name, declared)
    assert issubclass(cls, Params) or hasattr(cls, "from_dict")


def test_schema_defs_are_exactly_the_parameter_classes():
    assert set(SCHEMA["$defs"]) == set(_classes())


def test_every_section_refers_to_its_class():
    props = SCHEMA["properties"]
    for path, spec in SECTIONS.items():
        node = {"properties": props}
        for part in path.split("."):
            node = _resolve(node)["properties"][part]
        assert node.get("$ref") == f"#/$defs/{load_class(spec).__name__}", path
    topo = props["topology"]["properties"]
    assert {b: topo[b]["$ref"] for b in BUILTIN_BACKENDS} == \
        {b: f"#/$defs/{get_backend(b).params_cls.__name__}" for b in BUILTIN_BACKENDS}
    method = props["methods"]["additionalProperties"]
    assert method["properties"]["assembly"]["$ref"] == f"#/$defs/{load_class(SECTIONS['assembly']).__name__}"
    by_kind = {rule["if"]["properties"]["kind"]["const"]: rule["then"] for rule in method["allOf"]}
    for kind, cls in method_params().items():
        assert by_kind[kind]["properties"]["params"]["$ref"] == f"#/$defs/{cls.__name__}", kind
    suite = props["suites"]["additionalProperties"]["properties"]
    assert suite["benchmark"]["$ref"] == f"#/$defs/{load_class(SECTIONS['benchmark']).__name__}"
    assert [alt["$ref"] for alt in suite["source"]["oneOf"]] == \
        [f"#/$defs/{load_class(spec).__name__}" for spec in SOURCE_PARAMS.values()]


@pytest.mark.parametrize("kind", [k for k, spec in SOURCE_PARAMS.items() if issubclass(load_class(spec), SourceParams)])
def test_a_source_class_is_registered_under_its_own_kind_and_refuses_another(kind):
    cls = load_class(SOURCE_PARAMS[kind])
    assert cls.from_dict({"root": "data"}).kind == kind
    other = next(k for k in SOURCE_PARAMS if k != kind)
    with pytest.raises(ValueError, match=f"^{cls._label} kind must be '{kind}', got '{other}'$"):
        cls.from_dict({"root": "data", "kind": other})


def test_default_config_passes_schema_and_classes():
    jsonschema.Draft202012Validator.check_schema(SCHEMA)
    jsonschema.validate(CONFIG, SCHEMA)
    check_config(CONFIG, schema_sections(ROOT / "config/schema.yaml"))


def test_the_scaling_benchmark_rule_hands_the_script_every_section_it_reads():
    # benchmarks/scaling.py runs on a config file written from the rule's params: every config section the
    # script reads must be there (it read `methods` for phi_scene's settings while the rule left it out, and
    # `snakemake` (the whole workflow) failed at its last job), and phi_scene's settings must be the workflow's
    import re

    read = set(re.findall(r'cfg\["(\w+)"\]', (ROOT / "benchmarks/scaling.py").read_text()))
    settings = scaling_settings(CONFIG)
    assert read and read <= set(settings)
    assert method_assembly(settings, "phi_scene") == method_assembly(CONFIG, "phi_scene")
    assert "scaling_settings(config)" in (ROOT / "workflow/rules/report.smk").read_text()
