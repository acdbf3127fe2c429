"""Reprojection error of every calibration (Table I of the paper): SIFT matches
triangulated with poses and intrinsics held fixed, COLMAP's 4 px filter raised."""

REPROJECTION_CALIB = {
    "reg_a": ("reg_a", "reg_a.json"),
    "reg_b": ("reg_b", "rig.json"),
    "complete": ("calibration", "cameras.json"),
    "baseline_sfm": ("baseline", "cameras.json"),
    "ground_truth": ("ground_truth", "cameras.json"),
}


def reprojection_calibs(dataset):
    out = ["reg_a", "reg_b", "complete", "baseline_sfm"]
    return out + (["ground_truth"] if is_synthetic(dataset) else [])


def reprojection_views(wildcards):
    d = wildcards.dataset
    if wildcards.calib == "reg_a":
        return [res(d, "views", c, f"{centre(d)}.png") for c in cams(d)]
    if wildcards.calib == "ground_truth":
        # the ground truth covers every central view and one complete set
        full = full_set_cam(d)
        return sorted({res(d, "views", c, f"{centre(d)}.png") for c in cams(d)}
                      | {res(d, "views", full, f"{v}.png") for v in views(d)})
    return [res(d, "views", c, f"{v}.png") for c in cams(d) for v in views(d)]


rule reprojection_calib:
    input:
        calib=lambda wc: res(wc.dataset, *REPROJECTION_CALIB[wc.calib]),
        views=reprojection_views,
    output:
        "results/{dataset}/eval/reprojection/{calib}.json",
    wildcard_constraints:
        calib="|".join(REPROJECTION_CALIB),
    log:
        log_path("reprojection", "{dataset}_{calib}"),
    benchmark:
        bench_path("reprojection", "{dataset}_{calib}")
    threads: lambda wc: stage_config("sfm")["num_threads"]
    resources:
        mem_mb=8000,
        runtime=240,
    params:
        sfm=lambda wc: stage_config("sfm"),
        central=lambda wc: centre(wc.dataset),
    script:
        "../scripts/reprojection.py"


rule reprojection:
    input:
        evals=lambda wc: [res(wc.dataset, "eval", "reprojection", f"{c}.json")
                          for c in reprojection_calibs(wc.dataset)],
        baseline="results/{dataset}/baseline/baseline.json",
    output:
        "results/{dataset}/eval/reprojection.json",
    log:
        log_path("reprojection"),
    benchmark:
        bench_path("reprojection")
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    params:
        calibs=lambda wc: reprojection_calibs(wc.dataset),
    script:
        "../scripts/reprojection.py"


def reprojection_targets(dataset):
    return [res(dataset, "eval", "reprojection.json")]


TARGETS.append(reprojection_targets)
