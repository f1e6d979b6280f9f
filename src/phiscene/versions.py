"""Per-stage behaviour versions.

Each workflow rule passes its stage's version as a ``params:`` value, so that
bumping one here after a behaviour change reruns exactly the affected jobs
(Snakemake reruns a job whose params changed).
"""

BENCHMARK = 2
PROXIES = 2
TOPOLOGY = 3
GROUND = 6
METRICS = 4
TABLES = 2
REPORT = 1
