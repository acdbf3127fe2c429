"""View-synthesis experiments of Section III (Figs. 6-9): the inputs' depth maps
(rule depth_view, complete calibration) rendered by the project's DIBR or by RVS
(verify.renderer) with the complete calibration and, on synthetic data, with the
ground-truth cameras with the true depth, as the complete calibration too (the dB lost to
calibration, and to depth), and, with verify.ground_truth_own_depth, on maps estimated
with them (rule depth_view_truth)."""

from functools import partial

for _exp in (1, 2, 3):

    rule:
        name:
            f"synthesis_exp{_exp}"
        input:
            unpack(partial(synthesis_exp_join_inputs, exp=_exp)),
        output:
            json=report(
                f"results/{{dataset}}/eval/synthesis_exp{_exp}.json",
                caption="../report/synthesis.rst",
                category="View synthesis",
            ),
            synth=directory(f"results/{{dataset}}/eval/synth/exp{_exp}"),
        log:
            log_path(f"synthesis_exp{_exp}"),
        benchmark:
            bench_path(f"synthesis_exp{_exp}")
        priority: PRIORITY["synthesis"]
        conda:
            "../envs/plenocal.yaml"
        # one core: a two-core Exp. 3 (its targets share the job's cores) waited at the end
        # of the full run until both cores were free, and kept 1.35 of them busy
        threads: 1
        resources:
            mem_mb=4000,
            runtime=60,
        params:
            **synthesis_params(_exp),
        script:
            "../scripts/synthesis.py"


# A split experiment's camera sets (the complete calibration, the ground-truth cameras)
# render in jobs of their own, which the two cores run side by side; rule
# synthesis_exp<k> joins their runs into the result.
for _exp in SPLIT_EXPERIMENTS:

    rule:
        name:
            f"synthesis_exp{_exp}_part"
        input:
            unpack(partial(synthesis_exp_inputs, exp=_exp)),
        output:
            runs=f"results/{{dataset}}/eval/synthesis_exp{_exp}/{{cameras}}.json",
            kept=f"results/{{dataset}}/eval/synthesis_exp{_exp}/{{cameras}}.npz",
        log:
            log_path(f"synthesis_exp{_exp}_part", "{dataset}_{cameras}"),
        benchmark:
            bench_path(f"synthesis_exp{_exp}_part", "{dataset}_{cameras}")
        wildcard_constraints:
            cameras="complete|ground_truth",
        priority: PRIORITY["synthesis"]
        conda:
            "../envs/plenocal.yaml"
        threads: 1
        resources:
            mem_mb=4000,
            runtime=60,
        params:
            **synthesis_params(_exp, part=True),
        script:
            "../scripts/synthesis.py"


TARGETS.append(synthesis_targets)
