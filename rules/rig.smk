"""Registration B (Section II-C of the paper): the analytic N x N rig of one plenoptic
camera from the datasheet, the converter's disparity range and registration A's focal
length. One rig per dataset (the same camera took every shot)."""


rule rig_b:
    input:
        camera="data/{dataset}/camera.yaml",
        disparity=rig_b_disparities,
        reg_a="results/{dataset}/reg_a/reg_a.json",
    output:
        rig="results/{dataset}/reg_b/rig.json",
    log:
        log_path("rig_b"),
    benchmark:
        bench_path("rig_b")
    priority: PRIORITY["calibration"]
    conda:
        "../envs/plenocal.yaml"
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    params:
        rig=lambda wc: stage_config("rig"),
        views=lambda wc: n_views(wc.dataset),
        shots=lambda wc: cams(wc.dataset),
    script:
        "../scripts/rig_b.py"


TARGETS.append(rig_targets)
