"""Errors against ground truth (synthetic datasets) and the report page."""


rule gt_errors:
    input:
        truth="results/{dataset}/ground_truth/cameras.json",
        reg_a="results/{dataset}/reg_a/reg_a.json",
        rig="results/{dataset}/reg_b/rig.json",
        scale="results/{dataset}/merge/scale.json",
        calibration="results/{dataset}/calibration/cameras.json",
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
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    script:
        "../scripts/gt_errors.py"


def report_inputs(wildcards):
    """What the page shows, for the stages this workflow defines: a section whose
    producing rule is not included is reported as "not produced" instead of failing."""
    d = wildcards.dataset
    have = workflow.is_rule
    out = {}
    if have("reprojection"):
        out["reprojection"] = res(d, "eval", "reprojection.json")
    gt_rules = ("ground_truth", "map_a", "rig_b", "scale", "merge")
    if is_synthetic(d) and all(have(r) for r in gt_rules):
        out["gt_errors"] = res(d, "eval", "gt_errors.json")
    if is_synthetic(d) and have("ground_truth"):
        out["ground_truth"] = res(d, "ground_truth", "cameras.json")
    for k in (1, 2, 3):
        if have(f"synthesis_exp{k}"):
            out[f"exp{k}"] = res(d, "eval", f"synthesis_exp{k}.json")
    if have("merge"):
        out["calibration"] = res(d, "calibration", "cameras.json")
    if have("scale"):
        out["scale"] = res(d, "merge", "scale.json")
    if have("rig_b"):
        out["rig"] = res(d, "reg_b", "rig.json")
    if have("convert_quality"):
        out["convert_quality"] = res(d, "convert", "quality.json")
    if have("convert"):
        out["patch_size"] = [res(d, "views", c, "patch_size.png") for c in cams(d)]
    if have("depth"):
        out["depth"] = [res(d, "depth", r, f"{c}.png") for r in ("a", "b") for c in cams(d)]
    return out


rule report:
    input:
        unpack(report_inputs),
    output:
        html=report(
            "results/{dataset}/report/index.html",
            caption="../report/index.rst",
            category="Summary",
        ),
    params:
        results=lambda wc: res(wc.dataset),
        cams=lambda wc: cams(wc.dataset),
        views=lambda wc: n_views(wc.dataset),
        synthetic=lambda wc: is_synthetic(wc.dataset),
    log:
        log_path("report"),
    benchmark:
        bench_path("report")
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    script:
        "../scripts/report.py"


def report_targets(dataset):
    return [res(dataset, "report", "index.html")]


TARGETS.append(report_targets)
