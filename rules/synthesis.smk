"""View-synthesis experiments of Section III (Figs. 6-9): the inputs' depth maps
(rule depth_view, complete calibration) rendered by the project's DIBR or by RVS
(verify.renderer) with the complete calibration and, on synthetic data, with the
ground-truth cameras (same depth: the dB lost to calibration) and with the true depth
(the dB lost to depth)."""

from functools import partial

for _exp in (1, 2, 3):

    rule:
        name:
            f"synthesis_exp{_exp}"
        input:
            unpack(partial(synthesis_exp_inputs, exp=_exp)),
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
        conda:
            "../envs/plenocal.yaml"
        # Exp. 3 renders every view of the array four times: its targets share two cores
        threads: 2 if _exp == 3 else 1
        resources:
            mem_mb=4000,
            runtime=60,
        params:
            experiment=_exp,
            verify=lambda wc: stage_config("verify"),
            depth=lambda wc: synthesis_depth_config(),
            views_dir=lambda wc: res(wc.dataset, "views"),
            array_cams=lambda wc: array_cams(wc.dataset),
            n_views=lambda wc: n_views(wc.dataset),
        script:
            "../scripts/synthesis.py"


TARGETS.append(synthesis_targets)
