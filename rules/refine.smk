"""Joint refinement of every view of every shot under the rig (beyond the paper): the
Eq. 6 calibration of rule merge adjusted on the points refine.tracks names (both, the
default: the central views' matches of rule match_central carried into every view, and
every view's matches of rule view_matches), written in every export format to
calibration/ (plenocal.calib.refine). With refine.enabled false, calibration/ holds the
Eq. 6 result as it is."""


rule refine_tracks:
    input:
        unpack(refine_tracks_inputs),
    output:
        tracks=directory("results/{dataset}/refine/tracks/{source}"),
    log:
        log_path("refine_tracks", "{dataset}_{source}"),
    benchmark:
        bench_path("refine_tracks", "{dataset}_{source}")
    wildcard_constraints:
        source="central|views",
    priority: PRIORITY["calibration"]
    conda:
        "../envs/plenocal.yaml"
    # one job per source: on two cores the central views' set and every view's set are
    # made side by side, and the adjustments start from both (BENCHMARKS.md, "The refine
    # job's track sets as jobs of their own")
    threads: lambda wc: stage_config("refine")["num_threads"]
    resources:
        mem_mb=refine_tracks_mem_mb,
        runtime=30,
    params:
        refine=lambda wc: track_config(wc.source),
        sfm=lambda wc: sfm_params(),
    script:
        "../scripts/refine_tracks.py"


rule refine:
    input:
        unpack(refine_inputs),
    output:
        plain=report(
            "results/{dataset}/calibration/cameras.json",
            caption="../report/calibration.rst",
            category="Calibration",
        ),
        mpeg="results/{dataset}/calibration/mpeg/cameras.json",
        colmap=directory("results/{dataset}/calibration/colmap"),
        info="results/{dataset}/calibration/refine.json",
    log:
        log_path("refine"),
    benchmark:
        bench_path("refine")
    priority: PRIORITY["calibration"]
    conda:
        "../envs/plenocal.yaml"
    # refine.num_threads (1): the same bytes for any number (BENCHMARKS.md, "The refine job's
    # threads: the same bytes for any number"). With -j2, a two-thread job waits until both
    # cores are free at once, and the verification's one-thread jobs keep one busy (the full
    # run 430 s against 377 s); profiles/slurm gives it 2, where jobs do not share cores.
    # Every core where it is the run's only target (the calibration alone), since nothing
    # can run beside it then
    threads: lambda wc: sole_target_threads("refine", stage_config("refine")["num_threads"])
    resources:
        mem_mb=refine_mem_mb,
        runtime=30,
    params:
        refine=lambda wc: refine_config(),
        sfm=lambda wc: sfm_params(),
        hold_shot=lambda wc: full_set_cam(wc.dataset),
    script:
        "../scripts/refine.py"


TARGETS.append(refine_targets)
