"""View-synthesis experiments of Section III (Figs. 6-9): DIBR from plane-sweep depth
with the complete calibration and, on synthetic data, the ground-truth cameras."""


def synthesis_inputs(wildcards):
    d = wildcards.dataset
    out = {
        "calibration": res(d, "calibration", "cameras.json"),
        "rig": res(d, "reg_b", "rig.json"),
        "views": [res(d, "views", c, f"{v}.png") for c in array_cams(d) for v in views(d)],
    }
    if is_synthetic(d):
        out["truth"] = res(d, "ground_truth", "cameras.json")
    return out


for _exp in (1, 2, 3):

    rule:
        name:
            f"synthesis_exp{_exp}"
        input:
            unpack(synthesis_inputs),
        output:
            json=f"results/{{dataset}}/eval/synthesis_exp{_exp}.json",
            synth=directory(f"results/{{dataset}}/eval/synth/exp{_exp}"),
        log:
            log_path(f"synthesis_exp{_exp}"),
        benchmark:
            bench_path(f"synthesis_exp{_exp}")
        threads: 1
        resources:
            mem_mb=4000,
            runtime=60,
        params:
            experiment=_exp,
            verify=lambda wc: stage_config("verify"),
            depth=lambda wc: stage_config("depth"),
            views_dir=lambda wc: res(wc.dataset, "views"),
            array_cams=lambda wc: array_cams(wc.dataset),
            n_views=lambda wc: n_views(wc.dataset),
        script:
            "../scripts/synthesis.py"


def synthesis_targets(dataset):
    return [res(dataset, "eval", f"synthesis_exp{e}.json") for e in (1, 2, 3)]


TARGETS.append(synthesis_targets)
