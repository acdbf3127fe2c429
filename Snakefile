"""plenocal: calibration of plenoptic 2.0 camera arrays (see README.md)."""

import gc

from snakemake.utils import min_version

min_version("9.0")


configfile: "config.yaml"


report: "report/workflow.rst"


include: "rules/common.smk"


wildcard_constraints:
    dataset="|".join(re.escape(d) for d in DATASETS),
    cam=names.SHOT_PATTERN,
    view=names.VIEW_PATTERN,


include: "rules/simulate.smk"
include: "rules/convert.smk"
include: "rules/sfm.smk"
include: "rules/rig.smk"
include: "rules/depth.smk"
include: "rules/merge.smk"
include: "rules/refine.smk"
include: "rules/reprojection.smk"
include: "rules/synthesis.smk"
include: "rules/report.smk"
# last: stage names for --until / --forcerun, read from the rules above
include: "rules/stages.smk"


# every script rule's package code as a param: a change to it reruns that rule
add_code_params()


onstart:
    warn_stale_shot_folders()


rule all:
    default_target: True
    input:
        final_targets(),


# Last: what parsing made (Snakemake's modules, the rules, the config) lives as long as
# the process. Frozen, the cyclic collector no longer walks it, and neither does the
# interpreter's exit: a no-op rerun's exit took 0.20-0.23 s, now 0.03 s (issue 15).
# What the DAG and the jobs make later is collected as before.
gc.freeze()
