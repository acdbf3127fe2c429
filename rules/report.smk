"""Errors against ground truth (synthetic datasets) and the report page."""


rule gt_errors:
    input:
        truth="results/{dataset}/ground_truth/cameras.json",
        reg_a="results/{dataset}/reg_a/reg_a.json",
        rig="results/{dataset}/reg_b/rig.json",
        scale="results/{dataset}/merge/scale.json",
        calibration="results/{dataset}/calibration/cameras.json",
    output:
        errors="results/{dataset}/eval/gt_errors.json",
    log:
        log_path("gt_errors"),
    benchmark:
        bench_path("gt_errors")
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    script:
        "../scripts/gt_errors.py"
