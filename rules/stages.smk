"""Stage names a user can type: `snakemake --until convert`, `--forcerun depth`
(README's stage table).

Several stages run as jobs of several shots each, one rule per job (convert_0,
convert_views_1, depth_b_0, view_features_0, ...: a rule's outputs cannot depend on its
wildcards, and the batching is what keeps the run fast, issue 15), and Snakemake's
--until and --forcerun take rule names. So each such stage has a rule of its own name
that runs nothing: its inputs are every output of the stage's jobs in the default run
(common.smk default_run_outputs), so --until <stage> plans the stage and what it needs
and stops there. Named in --forcerun, it is a target of the DAG too, and its input
function, evaluated while the DAG is built and before Snakemake decides what runs, adds
the stage's rules to the rules forced: --forcerun <stage> runs every job of the stage
again and what depends on it. (--omit-from does not make its rules targets: it takes
the rules' own names.) (Added to --until's rules instead, a rule
of the stage that another one's job needs would stop there: Snakemake starts nothing
after a job of an --until rule.) A stage that is one rule (scale, merge, refine, report,
...) is that rule; a stage whose name a rule has is left to it. A stage's jobs of one
kind take the same kind of rule, by the name their rules share (convert_views,
depth_b, depth_b_other, view_features: the README's second table).

Included after every other rule file: the stages are read from the rules defined
(common.smk STAGE_RULES, stage_rules, stage_outputs).
Nothing here runs in a plain run: these rules are in the DAG only where named."""

from functools import partial

for _stage in STAGE_RULES:
    if workflow.is_rule(_stage) or not stage_rules(_stage):
        continue

    rule:
        name:
            _stage
        input:
            partial(stage_outputs, stage=_stage),
        localrule: True
