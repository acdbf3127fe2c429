"""Errors against ground truth (synthetic datasets) and the report page."""


rule gt_errors:
    input:
        truth="results/{dataset}/ground_truth/cameras.json",
        reg_a="results/{dataset}/reg_a/reg_a.json",
        rig="results/{dataset}/reg_b/rig.json",
        scale="results/{dataset}/merge/scale.json",
        calibration="results/{dataset}/calibration/cameras.json",
        eq6="results/{dataset}/calibration/eq6/cameras.json",
        refine="results/{dataset}/calibration/refine.json",
        model="results/{dataset}/reg_a/model",
    output:
        errors=report(
            "results/{dataset}/eval/gt_errors.json",
            caption="../report/gt_errors.rst",
            category="Ground truth",
        ),
    log:
        log_path("gt_errors"),
    benchmark:
        bench_path("gt_errors")
    wildcard_constraints:
        dataset=SYN,
    conda:
        "../envs/plenocal.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    script:
        "../scripts/gt_errors.py"


rule report:
    input:
        unpack(report_inputs),
    output:
        html=report(
            "results/{dataset}/report/index.html",
            caption="../report/index.rst",
            category="Summary",
        ),
    log:
        log_path("report"),
    benchmark:
        bench_path("report")
    conda:
        "../envs/plenocal.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    params:
        results=lambda wc: res(wc.dataset),
        cams=lambda wc: cams(wc.dataset),
        views=lambda wc: n_views(wc.dataset),
        synthetic=lambda wc: is_synthetic(wc.dataset),
    script:
        "../scripts/report.py"


TARGETS.append(report_targets)
