"""The workflow configuration (``config/config.yaml``): which parameter class reads each section, and its checks.

Every section of ``config.yaml`` that a stage reads is parsed by a :class:`~phiscene.params.Params`
dataclass (or, for a real-data source, a dataclass with the same ``from_dict`` contract). This module
names them in one place and offers the three things the workflow needs while it builds the DAG:

- :func:`deep_merge`: a method's ``assembly:`` override (or a suite's ``benchmark:`` override) merged
  over the defaults key by key at every depth, so ``assembly: {penetration_params: {eps: 0.01}}``
  keeps the other ``penetration_params`` keys of ``config.yaml``;
- :func:`method_assembly` (:func:`job_assembly`), :func:`bench_settings` and :func:`suite_proxies` (a suite's
  named ``proxy_profiles`` entry and its own override over ``proxies``): the merged mappings that jobs receive;
- :func:`check_config`: every parameter class run on its section (and on each merged override), so
  ``snakemake -n`` rejects a misspelled key before any job runs, with one line naming the config path
  and the key, e.g. ``config: assembly.penetration_params: unknown key 'epsilon' (known: backtrack_steps,
  eps, lr, ...)``.

Sections and their classes (``module:Class``, imported when a config is checked):

:data:`SECTIONS`
    Fixed paths: ``proxies``, ``sim``, ``assembly``, ``benchmark``, ``metrics.<name>``, ``export.demo``.
``proxy_profiles.<name>``
    :class:`~phiscene.proxies.ProxyParams`, merged over ``proxies`` (:func:`suite_proxies`).
:func:`method_params`
    ``methods.<name>.params`` by the method's ``kind``.
:data:`SOURCE_PARAMS`
    ``suites.<suite>.source`` by the source's ``kind``.
``topology.<backend>``
    The backend's own class (:func:`phiscene.topology.get_backend`).

``config/schema.yaml`` lists, for each of these sections, exactly the fields of its class
(``tests/test_config.py`` keeps the two in sync); the schema checks types and ranges, these classes
check keys and their own value rules.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import fields
from importlib import import_module
from pathlib import Path
from typing import Any

from phiscene.params import nested_params

__all__ = ["METHOD_PARAMS", "SECTIONS", "SOURCE_PARAMS", "STAGE_SECTIONS", "ConfigError", "bench_settings",
           "check_config", "check_params", "check_stage_config", "check_suite_benchmark", "deep_merge",
           "job_assembly", "load_class", "method_assembly", "method_params", "packaged_config_path", "proxy_profile",
           "schema_sections", "suite_generator", "suite_proxies"]

def packaged_config_path() -> Path:
    """The workflow's ``config/config.yaml`` as shipped with the package (``phiscene/defaults/config.yaml``, a link
    to it in the repository, the file itself in a built wheel): what the ``phiscene`` command reads where the
    working folder has no ``config/config.yaml``."""
    return Path(__file__).resolve().parent / "defaults" / "config.yaml"


#: Config path -> parameter class of the fixed sections.
SECTIONS: dict[str, str] = {
    "proxies": "phiscene.proxies:ProxyParams",
    "sim": "phiscene.sim.settings:SimSettings",
    "assembly": "phiscene.assembly.assemble:AssemblyParams",
    "benchmark": "phiscene.bench.build:BenchParams",
    "metrics.physical": "phiscene.metrics.physical:PhysicalParams",
    "metrics.recon": "phiscene.metrics.reconstruction:ReconParams",
    "metrics.alignment": "phiscene.metrics.alignment:AlignmentParams",
    "metrics.mujoco": "phiscene.sim.mujoco:MujocoParams",
    "metrics.pose": "phiscene.metrics.pose:PoseParams",
    "topology.attached": "phiscene.topology.attached:AttachedParams",
    "export.demo": "phiscene.demo:DemoParams",
}

#: Method kinds with ``params`` besides the registered baselines (:mod:`phiscene.baselines.registry`), by class.
METHOD_PARAMS: dict[str, str] = {
    "external": "phiscene.baselines.external:ImportParams",
}


def method_params() -> dict[str, type]:
    """Method kind -> parameter class of its ``methods.<name>.params``: every registered baseline's class and
    :data:`METHOD_PARAMS` (a kind not listed takes no check)."""
    from phiscene.baselines.registry import BASELINES

    return {**{k: b.params for k, b in BASELINES.items()}, **{k: load_class(v) for k, v in METHOD_PARAMS.items()}}


#: Real-data source kind -> parameter class of ``suites.<suite>.source``.
SOURCE_PARAMS: dict[str, str] = {
    "front3d": "phiscene.io.front3d:Front3dParams",
    "rest3d": "phiscene.io.rest3d:Rest3dSource",
    "sam3d": "phiscene.io.sam3d:Sam3dSource",
    "placed": "phiscene.io.placed_suite:PlacedSource",
}


class ConfigError(ValueError):
    """A bad ``config.yaml`` value; the message is one line starting ``config: <path>:``."""


def load_class(spec: str) -> type:
    """The class named by ``"module:Class"``."""
    module, _, name = spec.partition(":")
    return getattr(import_module(module), name)


def deep_merge(base: Mapping[str, Any] | None, override: Mapping[str, Any] | None) -> dict:
    """``override`` merged over ``base`` at every depth (neither argument is modified).

    A key whose values are mappings on both sides is merged recursively; any other value of
    ``override`` (a scalar, a list, ``None``) replaces the one of ``base``.

    Examples
    --------
    >>> deep_merge({"a": 1, "p": {"eps": 0.005, "lr": 0.005}}, {"p": {"eps": 0.01}})
    {'a': 1, 'p': {'eps': 0.01, 'lr': 0.005}}
    """
    out = {k: (deep_merge(v, None) if isinstance(v, Mapping) else v) for k, v in (base or {}).items()}
    for key, value in (override or {}).items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = deep_merge(out[key], value)
        elif isinstance(value, Mapping):
            out[key] = deep_merge(value, None)
        else:
            out[key] = value
    return out


#: The config sections ``benchmarks/scaling.py`` reads (:func:`scaling_settings`).
SCALING_SECTIONS = ("benchmark", "sim", "proxies", "topology", "assembly", "methods", "metrics")


def scaling_settings(config: Mapping[str, Any]) -> dict:
    """The config sections ``benchmarks/scaling.py`` reads: the params of the workflow's ``scaling_benchmark`` rule,
    written to the config file it runs with (it times ``phi_scene`` as configured: :func:`method_assembly`)."""
    return {k: config[k] for k in SCALING_SECTIONS}


def method_assembly(config: Mapping[str, Any], method: str) -> dict:
    """The ``assembly`` settings of a ``phi_scene``-kind method: its override deep-merged over ``assembly``."""
    return deep_merge(config.get("assembly"), config["methods"][method].get("assembly"))


def job_assembly(config: Mapping[str, Any], method: str) -> dict:
    """The ``assembly`` settings a method's grounding jobs receive (their params): :func:`method_assembly`, less the
    ``faithful`` settings of a method with faithful grounding off, which do not act on its result (the paper's loop).

    A change to those settings (tuning ``phi_scene``'s faithful grounding in the global ``assembly``) then reruns
    the faithful methods only, not ``phi_scene_paper`` and the ablations.
    """
    merged = method_assembly(config, method)
    faithful = merged.get("faithful")
    if isinstance(faithful, Mapping) and not faithful.get("enabled", False):
        merged = {**merged, "faithful": {"enabled": False}}
    return merged


def proxy_profile(config: Mapping[str, Any], name: str, where: str) -> dict:
    """The proxy settings of the named profile: ``proxy_profiles.<name>`` (a partial ``proxies`` section)
    deep-merged over ``proxies``.

    Raises
    ------
    ConfigError
        ``config: <where>: no proxy profile 'name' (known: ...)``.
    """
    profiles = _mapping(config.get("proxy_profiles"), "proxy_profiles")
    if name not in profiles:
        raise ConfigError(f"config: {where}: no proxy profile {name!r} (known: "
                          f"{', '.join(sorted(profiles)) or 'none; define it under proxy_profiles'})")
    return deep_merge(config.get("proxies"), _mapping(profiles[name], f"proxy_profiles.{name}"))


def suite_proxies(config: Mapping[str, Any], suite: str | None = None) -> dict:
    """The proxy settings of a suite's scenes (the params of the workflow's ``proxies`` rule).

    ``proxies``, then the named profile the suite takes (``suites.<suite>.proxy_profile``, a key of
    ``proxy_profiles``: ``reconstruction``, the lighter CoACD search made for 30k-face reconstructions), then the
    suite's own ``proxies`` override, each deep-merged over the one before; ``suite=None`` gives ``proxies`` alone.

    Raises
    ------
    ConfigError
        The suite names a profile that ``proxy_profiles`` does not define.
    """
    if suite is None:
        return deep_merge(config.get("proxies"), None)
    spec = config["suites"][suite]
    profile = spec.get("proxy_profile")
    base = config.get("proxies") if profile is None else proxy_profile(config, str(profile),
                                                                       f"suites.{suite}.proxy_profile")
    return deep_merge(base, spec.get("proxies"))


def suite_generator(config: Mapping[str, Any], suite: str) -> str:
    """The embedded benchmark generator that builds a suite's scenes (a key of
    :data:`phiscene.bench.templates.TEMPLATES`: ``contact``, ``rooms``, ``clutter``).

    ``suites.<suite>.generator``, else the suite's own name. A suite of another name built by one of them (a
    held-out seed or another degradation, beside the default suites in the same ``results/``) names it; the same
    generator, seed and scene index give the same ground truth whatever the suite is called.

    Raises
    ------
    ConfigError
        No embedded generator builds the suite: it reads real data (``source``), or no generator has that name.
    """
    from phiscene.bench.build import TEMPLATES  # importing build registers every generator

    spec = config["suites"][suite]
    if "source" in spec:
        raise ConfigError(f"config: suites.{suite}: read from real data (`source`), not built by an embedded "
                          "benchmark generator")
    generator = str(spec.get("generator", suite))
    if generator not in TEMPLATES:
        hint = "" if "generator" in spec else ("; a suite of another name says which builds it "
                                               "(`generator: <one of them>`)")
        raise ConfigError(f"config: suites.{suite}: no embedded benchmark generator {generator!r} (known: "
                          f"{', '.join(sorted(TEMPLATES))}){hint}, or give a real-data `source`")
    return generator


def bench_settings(config: Mapping[str, Any], suite: str) -> dict:
    """The benchmark settings of a suite's scenes (the params of the benchmark rule).

    ``benchmark`` with the suite's ``benchmark`` override deep-merged over it, plus the shared ``sim``
    and ``proxies`` sections; :func:`phiscene.bench.build.build_scene` completes it from the suite's
    defaults.
    """
    merged = deep_merge(config.get("benchmark"), config["suites"][suite].get("benchmark"))
    return {**merged, "sim": config.get("sim") or {}, "proxies": config.get("proxies") or {}}


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())


def check_params(cls: type, data: Any, path: str) -> Any:
    """Parse ``data`` with parameter class ``cls``, or raise :class:`ConfigError` naming ``path``.

    Unknown keys are looked for at every nesting level first (nested :class:`~phiscene.params.Params`
    fields), so the error names the deepest path; then ``cls.from_dict`` runs the class's own checks.

    Parameters
    ----------
    cls
        A dataclass with a ``from_dict`` class method (a :class:`~phiscene.params.Params` subclass).
    data
        The section: a mapping, or ``None`` for the defaults.
    path
        Its dotted config path (``assembly``, ``methods.seq_sdf_only.assembly``, ...).

    Returns
    -------
    The parsed instance.

    Raises
    ------
    ConfigError
        ``config: <path>: unknown key 'k' (known: ...)``, ``config: <path>: expected a mapping ...``
        or ``config: <path>: <the class's own ValueError>``.
    """
    if data is None:
        data = {}
    if not isinstance(data, Mapping):
        raise ConfigError(f"config: {path}: expected a mapping of {cls.__name__} keys, got {data!r}")
    known = sorted(f.name for f in fields(cls))
    unknown = sorted(set(map(str, data)) - set(known))
    if unknown:
        keys = ", ".join(repr(k) for k in unknown)
        raise ConfigError(f"config: {path}: unknown key{'s' if len(unknown) > 1 else ''} {keys} "
                          f"(known: {', '.join(known)})")
    for name, sub in nested_params(cls).items():
        if name in data and not isinstance(data[name], sub):
            check_params(sub, data[name], f"{path}.{name}")
    try:
        return cls.from_dict(data)
    except (ValueError, TypeError) as exc:
        raise ConfigError(f"config: {path}: {_one_line(exc)}") from None


def _section(config: Mapping[str, Any], path: str) -> tuple[bool, Any]:
    """(present, value) of a dotted path."""
    node: Any = config
    for part in path.split("."):
        if not isinstance(node, Mapping) or part not in node:
            return False, None
        node = node[part]
    return True, node


def _mapping(value: Any, path: str) -> Mapping:
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise ConfigError(f"config: {path}: expected a mapping, got {value!r}")
    return value


def schema_sections(schema_path: str | Path) -> list[str]:
    """Top-level sections a config may have: the ``properties`` of ``config/schema.yaml``."""
    import yaml

    with open(schema_path, encoding="utf-8") as f:
        return sorted(yaml.safe_load(f)["properties"])


#: The fixed sections that grounding, measuring and exporting one scene read (:func:`check_stage_config`).
STAGE_SECTIONS = ("proxies", "sim", "assembly", "metrics.physical", "metrics.mujoco", "topology.attached",
                  "export.demo")


def check_stage_config(config: Mapping[str, Any]) -> None:
    """The part of :func:`check_config` that the ``phiscene`` command's stages read; raise one :class:`ConfigError`.

    Checked: the :data:`STAGE_SECTIONS`, every ``proxy_profiles`` entry and every suite's proxy settings
    (:func:`suite_proxies`), ``topology.<backend>`` with the backend's class and every ``phi_scene``-kind method's
    merged ``assembly``. Not the benchmark generators, baselines, real-data sources or tables, whose classes
    import what grounding one scene does not need.

    Raises
    ------
    ConfigError
        One line: ``config: <path>: <problem>``.
    """
    config = _mapping(config, "(top level)")
    for path in STAGE_SECTIONS:
        present, value = _section(config, path)
        if present:
            check_params(load_class(SECTIONS[path]), value, path)
    for name in _mapping(config.get("proxy_profiles"), "proxy_profiles"):
        where = f"proxy_profiles.{name}"
        check_params(load_class(SECTIONS["proxies"]), proxy_profile(config, name, where), where)
    for suite, spec in _mapping(config.get("suites"), "suites").items():
        spec = _mapping(spec, f"suites.{suite}")
        if "proxies" in spec or "proxy_profile" in spec:
            where = f"suites.{suite}.proxies" if "proxies" in spec else f"suites.{suite}.proxy_profile"
            check_params(load_class(SECTIONS["proxies"]), suite_proxies(config, suite), where)

    from phiscene.topology import backend_names, get_backend

    for backend, settings in _mapping(config.get("topology"), "topology").items():
        if backend == "attached":  # the attachment decision every backend runs (SECTIONS)
            continue
        if backend not in backend_names():
            raise ConfigError(f"config: topology: unknown backend {backend!r} (known: {', '.join(backend_names())})")
        check_params(get_backend(backend).params_cls, settings, f"topology.{backend}")
    for name, spec in _mapping(config.get("methods"), "methods").items():
        spec = _mapping(spec, f"methods.{name}")
        if spec.get("kind") == "phi_scene":
            _mapping(spec.get("assembly"), f"methods.{name}.assembly")  # a non-mapping override: one line too
            check_params(load_class(SECTIONS["assembly"]), method_assembly(config, name), f"methods.{name}.assembly")


def check_suite_benchmark(config: Mapping[str, Any], suite: str) -> None:
    """A generated suite's benchmark settings: its own ``benchmark`` override, then :func:`bench_settings` completed
    by its generator's defaults (what the benchmark rule and ``phiscene bench`` build with).

    Raises
    ------
    ConfigError
        A bad key or value (``config: suites.<suite>.benchmark...``), or no generator builds the suite
        (:func:`suite_generator`).
    """
    from phiscene.bench.build import BenchParams, with_suite_defaults

    generator = suite_generator(config, suite)
    check_params(BenchParams, config["suites"][suite].get("benchmark"), f"suites.{suite}.benchmark")
    check_params(BenchParams, with_suite_defaults(generator, bench_settings(config, suite)),
                 f"suites.{suite}.benchmark")


def check_config(config: Mapping[str, Any], sections: list[str] | None = None) -> None:
    """Run every parameter class on its config section; raise one :class:`ConfigError` for the first bad one.

    Checked: unknown top-level sections (when ``sections`` is given), the fixed :data:`SECTIONS`, the proxy
    profiles and settings, topology backends and ``phi_scene``-kind methods of :func:`check_stage_config`,
    every suite's merged benchmark settings (:func:`bench_settings`) and real-data ``source``, every baseline's
    ``params`` (:func:`method_params`) and the tables (:func:`check_tables`).

    Parameters
    ----------
    config
        The workflow config (``config.yaml`` with any ``--configfile`` overrides merged).
    sections
        Known top-level sections (:func:`schema_sections` of ``config/schema.yaml``); ``None`` skips
        that check.

    Raises
    ------
    ConfigError
        One line: ``config: <path>: <problem>``.
    """
    config = _mapping(config, "(top level)")
    if sections is not None:
        unknown = sorted(set(config) - set(sections))
        if unknown:
            raise ConfigError(f"config: unknown section {unknown[0]!r} (known: {', '.join(sorted(sections))})")
    for path, spec in SECTIONS.items():
        present, value = _section(config, path)
        if present and path not in STAGE_SECTIONS:
            check_params(load_class(spec), value, path)
    check_stage_config(config)

    for suite, spec in _mapping(config.get("suites"), "suites").items():
        spec = _mapping(spec, f"suites.{suite}")
        if "source" in spec:
            if "generator" in spec:
                raise ConfigError(f"config: suites.{suite}: `generator` and `source` exclude each other (a suite "
                                  "is built by an embedded generator or read from real data)")
            source = _mapping(spec["source"], f"suites.{suite}.source")
            kind = source.get("kind")
            if kind not in SOURCE_PARAMS:
                raise ConfigError(f"config: suites.{suite}.source.kind: unknown source kind {kind!r} "
                                  f"(known: {', '.join(sorted(SOURCE_PARAMS))})")
            check_params(load_class(SOURCE_PARAMS[kind]), source, f"suites.{suite}.source")
        else:
            check_suite_benchmark(config, suite)

    for name, spec in _mapping(config.get("methods"), "methods").items():
        spec = _mapping(spec, f"methods.{name}")
        kind = spec.get("kind")
        if kind != "phi_scene" and kind in method_params():
            check_params(method_params()[kind], spec.get("params"), f"methods.{name}.params")
            from phiscene.baselines.registry import BASELINES

            if kind in BASELINES and "topology" in BASELINES[kind].needs and not spec.get("topology"):
                raise ConfigError(f"config: methods.{name}.topology: a {kind} baseline places by a support graph: "
                                  "name its topology backend")

    check_tables(config)


def check_tables(config: Mapping[str, Any]) -> None:
    """Every ``tables.<name>`` entry: a registered kind on a configured suite, with its rows configured.

    Raises
    ------
    ConfigError
        One line naming the entry and the problem (unknown kind or suite, missing rows, an unknown method
        or topology backend).
    """
    from phiscene.table_registry import TABLE_KINDS
    from phiscene.topology import backend_names

    suites = _mapping(config.get("suites"), "suites")
    methods = _mapping(config.get("methods"), "methods")
    for name, spec in _mapping(config.get("tables"), "tables").items():
        spec = _mapping(spec, f"tables.{name}")
        kind = spec.get("kind", name)
        if kind not in TABLE_KINDS:
            raise ConfigError(f"config: tables.{name}.kind: unknown table kind {kind!r} "
                              f"(known: {', '.join(TABLE_KINDS)})")
        if spec.get("suite") not in suites:
            raise ConfigError(f"config: tables.{name}.suite: unknown suite {spec.get('suite')!r} "
                              f"(known: {', '.join(suites)})")
        rows = TABLE_KINDS[kind].rows
        if rows is None:
            continue
        if not spec.get(rows):
            raise ConfigError(f"config: tables.{name}: a {kind} table needs a list of {rows}")
        known = list(methods) if rows == "methods" else backend_names()
        for row in spec[rows]:
            if row not in known:
                raise ConfigError(f"config: tables.{name}.{rows}: unknown {rows[:-1]} {row!r} "
                                  f"(known: {', '.join(known)})")

