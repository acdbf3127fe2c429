"""Reprojection error of every calibration (Table I of the paper): the SIFT matches of
rule view_matches triangulated with poses and intrinsics held fixed, COLMAP's 4 px
filter raised."""


rule reprojection_calib:
    input:
        calib=lambda wc: res(wc.dataset, *REPROJECTION_CALIB[wc.calib]),
        database="results/{dataset}/matches/database.db",
    output:
        "results/{dataset}/eval/reprojection/{calib}.json",
    log:
        log_path("reprojection", "{dataset}_{calib}"),
    benchmark:
        bench_path("reprojection", "{dataset}_{calib}")
    wildcard_constraints:
        # the complete calibration's row: rule reprojection_complete
        calib="|".join(c for c in REPROJECTION_CALIB if c != "complete"),
    priority: reprojection_priority
    conda:
        "../envs/plenocal.yaml"
    threads: lambda wc: stage_config("sfm")["num_threads"]
    resources:
        # grows with the view database: 0.69 GB on the default data (700 views)
        mem_mb=reprojection_mem_mb,
        runtime=240,
    params:
        sfm=lambda wc: sfm_params("reprojection"),
        central=lambda wc: centre(wc.dataset),
    script:
        "../scripts/reprojection.py"


# Table I's row of the calibration in calibration/ (as reprojection_calib's), and its
# triangulation written as a COLMAP model with coloured 3-D points: the calibration's
# cameras, one per view, for the tools that start from COLMAP's points (Gaussian splatting)
rule reprojection_complete:
    input:
        calib="results/{dataset}/calibration/cameras.json",
        database="results/{dataset}/matches/database.db",
        view_sets=lambda wc: view_sets(wc.dataset, cams(wc.dataset)),
    output:
        json="results/{dataset}/eval/reprojection/complete.json",
        model=directory("results/{dataset}/calibration/colmap_points"),
    log:
        log_path("reprojection", "{dataset}_complete"),
    benchmark:
        bench_path("reprojection", "{dataset}_complete")
    conda:
        "../envs/plenocal.yaml"
    threads: lambda wc: stage_config("sfm")["num_threads"]
    resources:
        # grows with the view database: 0.69 GB on the default data (700 views)
        mem_mb=reprojection_mem_mb,
        runtime=240,
    params:
        sfm=lambda wc: sfm_params("reprojection"),
        central=lambda wc: centre(wc.dataset),
    script:
        "../scripts/reprojection.py"


# every view cropped about its principal point and named <shot>_<r>_<c>.png, with
# colmap_points' model: the dataset the reference 3D Gaussian splatting code trains on
# (export.gaussian_splatting puts it in the default run; asked for by path, it is made)
rule gaussian_splatting:
    input:
        model="results/{dataset}/calibration/colmap_points",
        view_sets=lambda wc: view_sets(wc.dataset, cams(wc.dataset)),
    output:
        directory("results/{dataset}/calibration/gaussian_splatting"),
    log:
        log_path("gaussian_splatting"),
    benchmark:
        bench_path("gaussian_splatting")
    conda:
        "../envs/plenocal.yaml"
    threads: 1
    resources:
        mem_mb=600,
        runtime=30,
    script:
        "../scripts/gaussian_splatting.py"


rule reprojection:
    input:
        evals=lambda wc: [
            res(wc.dataset, "eval", "reprojection", f"{c}.json")
            for c in reprojection_calibs(wc.dataset)
        ],
        baseline="results/{dataset}/baseline/baseline.json",
        scratch=scratch_sfm_input,
    output:
        report(
            "results/{dataset}/eval/reprojection.json",
            caption="../report/reprojection.rst",
            category="Table I",
        ),
    log:
        log_path("reprojection"),
    benchmark:
        bench_path("reprojection")
    conda:
        "../envs/plenocal.yaml"
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    params:
        calibs=lambda wc: reprojection_calibs(wc.dataset),
    script:
        "../scripts/reprojection.py"


TARGETS.append(reprojection_targets)
TARGETS.append(gaussian_splatting_targets)
