# Per-scene metrics: results/metrics/{method}/{suite}/{scene}.json of every method a table shows on the suite,
# each with the sections its tables read (phiscene.metrics.evaluate; see metric_groups in common.smk).
# One job per scene computes the files of a group of methods (those shown by the same tables): the simulators and
# mesh libraries take longer to import than most metrics take to compute, so one process per (method, scene)
# would spend half its time importing. One rule per (suite, group), since the outputs differ between them.

for _suite in config["suites"]:
    for _group, _methods in metric_groups(_suite).items():

        rule:
            name:
                f"metrics_{_suite}_{_group}"
            input:
                unpack(lambda wc, suite=_suite, methods=_methods: metrics_inputs(suite, methods, wc.scene)),
            output:
                [f"results/metrics/{m}/{_suite}/{{scene}}.json" for m in _methods],
            params:
                tasks=metric_tasks(_suite, _methods),
                settings=metric_settings(_suite, _methods),
                cache_dir=CACHE,
                version=V.METRICS,
            log:
                f"results/logs/metrics/{_suite}/{_group}/{{scene}}.log",
            benchmark:
                f"results/benchmarks/metrics/{_group}/{_suite}/{{scene}}.tsv"
            threads: 1
            resources:
                mem_mb=1500,
                runtime=30,
            conda:
                ENV
            script:
                "../scripts/metrics.py"
