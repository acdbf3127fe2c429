"""plenocal: calibration of plenoptic 2.0 camera arrays (see README.md)."""

from snakemake.utils import min_version

min_version("9.0")


configfile: "config.yaml"


include: "rules/common.smk"
include: "rules/simulate.smk"


rule all:
    input:
        final_targets(),
    default_target: True
