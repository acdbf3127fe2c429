"""Registration A (Section II-B of the paper): structure-from-motion of the central
view of every shot (array + hand-held), the matches of all views that the verification
shares (SIFT per shot in view_features, which needs no calibration and runs alongside
the conversion and A; the matching of A's neighbouring shots in view_matches), and the
naive baselines of Table I (A+SfM; SfM of all views from scratch)."""


rule features_a:
    input:
        views=central_views,
    output:
        db="results/{dataset}/reg_a/features.db",
        images=directory("results/{dataset}/reg_a/images"),
        info="results/{dataset}/reg_a/features.json",
    log:
        log_path("features_a"),
    benchmark:
        bench_path("features_a")
    priority: PRIORITY["chain"]
    conda:
        "../envs/plenocal.yaml"
    threads: lambda wc: stage_config("sfm")["num_threads"]
    resources:
        mem_mb=4000,
        runtime=30,
        # SiftGPU and the GPU matcher where sfm.device is cuda (a GPU node on a cluster)
        gpu=gpus("sfm", "device"),
    params:
        sfm=lambda wc: sfm_params(),
    script:
        "../scripts/features_a.py"


rule match_a:
    input:
        db="results/{dataset}/reg_a/features.db",
    output:
        db="results/{dataset}/reg_a/database.db",
        info="results/{dataset}/reg_a/matches.json",
    log:
        log_path("match_a"),
    benchmark:
        bench_path("match_a")
    priority: PRIORITY["chain"]
    conda:
        "../envs/plenocal.yaml"
    threads: lambda wc: stage_config("sfm")["num_threads"]
    resources:
        mem_mb=4000,
        runtime=30,
        gpu=gpus("sfm", "device"),
    params:
        sfm=lambda wc: sfm_params(),
    script:
        "../scripts/match_a.py"


rule match_central:
    input:
        views=central_views,
    output:
        db="results/{dataset}/matches/central.db",
        info="results/{dataset}/matches/central.json",
    log:
        log_path("match_central"),
    benchmark:
        bench_path("match_central")
    priority: PRIORITY["calibration"]
    conda:
        "../envs/plenocal.yaml"
    threads: lambda wc: stage_config("sfm")["num_threads"]
    resources:
        mem_mb=4000,
        runtime=30,
        gpu=gpus("sfm", "device"),
    params:
        sfm=lambda wc: sfm_params(),
        contrast=lambda wc: stage_config("refine")["central_contrast"],
    script:
        "../scripts/match_central.py"


rule map_a:
    input:
        db="results/{dataset}/reg_a/database.db",
        images="results/{dataset}/reg_a/images",
    output:
        model=directory("results/{dataset}/reg_a/model"),
        reg_a="results/{dataset}/reg_a/reg_a.json",
    log:
        log_path("map_a"),
    benchmark:
        bench_path("map_a")
    priority: PRIORITY["chain"]
    conda:
        "../envs/plenocal.yaml"
    threads: lambda wc: stage_config("sfm")["num_threads"]
    resources:
        mem_mb=4000,
        runtime=60,
    params:
        sfm=lambda wc: sfm_params("mapper"),
    script:
        "../scripts/map_a.py"


# SIFT of every view, SHOTS_PER_JOB shots a job (view_features_0, view_features_1, ...:
# a job's start-up, importing COLMAP and OpenCV, is 1.4 s beside 2.1 s of SIFT a shot),
# one database per shot, each job as soon as its shots are converted.
for _i, _d in enumerate(DATASETS):
    for _k, _chunk in enumerate(shot_chunks(cams(_d))):

        rule:
            name:
                chunk_rule("view_features", _i, _k)
            input:
                view_sets=[view_set(_d, c) for c in _chunk],
            output:
                [res(_d, "matches", "features", f"{c}.db") for c in _chunk],
            log:
                dataset_path(
                    _d, log_path("view_features", f"{_d}_{chunk_label(_chunk)}")
                ),
            benchmark:
                dataset_path(
                    _d, bench_path("view_features", f"{_d}_{chunk_label(_chunk)}")
                )
            priority: PRIORITY["views"]
            conda:
                "../envs/plenocal.yaml"
            threads: lambda wc: stage_config("sfm")["num_threads"]
            resources:
                mem_mb=1000,
                runtime=30,
                gpu=gpus("sfm", "device"),
            params:
                sfm=lambda wc: sfm_params(),
            script:
                "../scripts/view_features.py"


rule view_matches:
    input:
        features=lambda wc: [
            res(wc.dataset, "matches", "features", f"{c}.db") for c in cams(wc.dataset)
        ],
        reg_a="results/{dataset}/reg_a/reg_a.json",
    output:
        database="results/{dataset}/matches/database.db",
        info="results/{dataset}/matches/matches.json",
    log:
        log_path("view_matches"),
    benchmark:
        bench_path("view_matches")
    priority: PRIORITY["chain"]
    conda:
        "../envs/plenocal.yaml"
    threads: lambda wc: stage_config("sfm")["view_matching"]["num_threads"]
    resources:
        mem_mb=4000,
        runtime=60,
        gpu=gpus("sfm", "device"),
    params:
        sfm=lambda wc: sfm_params("view_matching"),
    script:
        "../scripts/view_matches.py"


rule baseline_sfm:
    input:
        reg_a="results/{dataset}/reg_a/reg_a.json",
        database="results/{dataset}/matches/database.db",
    output:
        cameras="results/{dataset}/baseline/cameras.json",
        info="results/{dataset}/baseline/baseline.json",
    log:
        log_path("baseline_sfm"),
    benchmark:
        bench_path("baseline_sfm")
    priority: PRIORITY["chain"]
    conda:
        "../envs/plenocal.yaml"
    threads: lambda wc: stage_config("sfm")["num_threads"]
    resources:
        mem_mb=8000,
        runtime=240,
    params:
        sfm=lambda wc: sfm_params(),
        central=lambda wc: centre(wc.dataset),
    script:
        "../scripts/baseline_sfm.py"


rule baseline_scratch:
    input:
        database="results/{dataset}/matches/database.db",
    output:
        "results/{dataset}/baseline/scratch.json",
    log:
        log_path("baseline_scratch"),
    benchmark:
        bench_path("baseline_scratch")
    conda:
        "../envs/plenocal.yaml"
    threads: lambda wc: stage_config("sfm")["num_threads"]
    resources:
        mem_mb=8000,
        runtime=240,
    params:
        sfm=lambda wc: sfm_params(),
    script:
        "../scripts/baseline_scratch.py"


TARGETS.append(sfm_targets)
