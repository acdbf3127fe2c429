"""Scale between the registrations (Eq. 5) and their merge (Eq. 6): the paper's complete
calibration, written in every export format to calibration/eq6/ (rule refine, in
rules/refine.smk, makes calibration/ from it)."""


rule scale:
    input:
        depth_a=lambda wc: [
            res(wc.dataset, "depth", "a", f"{c}.npy") for c in scale_shots(wc.dataset)
        ],
        depth_b=lambda wc: [
            res(wc.dataset, "depth", "b", f"{c}.npy") for c in scale_shots(wc.dataset)
        ],
        # the stage's step over registration A's array spacing, beside Eq. 5
        reg_a="results/{dataset}/reg_a/reg_a.json",
        camera="data/{dataset}/camera.yaml",
    output:
        scale="results/{dataset}/merge/scale.json",
    log:
        log_path("scale"),
    benchmark:
        bench_path("scale")
    priority: PRIORITY["calibration"]
    conda:
        "../envs/plenocal.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=5,
    params:
        scale=lambda wc: stage_config("scale"),
        shots=lambda wc: scale_shots(wc.dataset),
    script:
        "../scripts/scale.py"


rule merge:
    input:
        reg_a="results/{dataset}/reg_a/reg_a.json",
        rig="results/{dataset}/reg_b/rig.json",
        scale="results/{dataset}/merge/scale.json",
    output:
        plain="results/{dataset}/calibration/eq6/cameras.json",
        mpeg="results/{dataset}/calibration/eq6/mpeg/cameras.json",
        colmap=directory("results/{dataset}/calibration/eq6/colmap"),
    log:
        log_path("merge"),
    benchmark:
        bench_path("merge")
    priority: PRIORITY["calibration"]
    conda:
        "../envs/plenocal.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    params:
        shots=lambda wc: cams(wc.dataset),
    script:
        "../scripts/merge.py"


TARGETS.append(merge_targets)


rule mpeg_views:
    """Depth maps, textures and RVS configurations beside the MPEG camera JSON."""
    input:
        unpack(mpeg_views_inputs),
    output:
        depth=directory("results/{dataset}/calibration/mpeg/depth"),
        texture=directory("results/{dataset}/calibration/mpeg/texture"),
        rvs=directory("results/{dataset}/calibration/mpeg/rvs"),
    log:
        log_path("mpeg_views"),
    benchmark:
        bench_path("mpeg_views")
    conda:
        "../envs/plenocal.yaml"
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    params:
        array_cams=lambda wc: array_cams(wc.dataset),
        n_views=lambda wc: n_views(wc.dataset),
        verify=lambda wc: {
            k: stage_config("verify")[k]
            for k in ("exp2_sets", "exp3_view_stride", "rvs_blending_factor")
        },
    script:
        "../scripts/mpeg_views.py"


TARGETS.append(mpeg_views_targets)
