"""plenocal: calibration of plenoptic 2.0 camera arrays (see README.md)."""

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
include: "rules/reprojection.smk"
include: "rules/synthesis.smk"
include: "rules/report.smk"


rule all:
    default_target: True
    input:
        final_targets(),
