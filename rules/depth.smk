"""Depth of the central view of every shot in registration A (central views of the
nearest shots, SfM units) and in registration B (views of its own set, metres): both in
one job per shot (plenocal.depth.shot)."""


rule depth:
    input:
        unpack(depth_inputs),
    output:
        depth_a="results/{dataset}/depth/a/{cam}.npy",
        preview_a=report(
            "results/{dataset}/depth/a/{cam}.png",
            caption="../report/depth.rst",
            category="Depth",
            subcategory="registration a",
        ),
        info_a="results/{dataset}/depth/a/{cam}.json",
        depth_b="results/{dataset}/depth/b/{cam}.npy",
        preview_b=report(
            "results/{dataset}/depth/b/{cam}.png",
            caption="../report/depth.rst",
            category="Depth",
            subcategory="registration b",
        ),
        info_b="results/{dataset}/depth/b/{cam}.json",
    log:
        log_path("depth", "{cam}"),
    benchmark:
        bench_path("depth", "{cam}")
    priority: depth_priority
    conda:
        "../envs/plenocal.yaml"
    threads: 1
    resources:
        mem_mb=3000,
        runtime=60,
        # COLMAP's patch-match stereo needs a GPU node; the plane sweep does not
        gpu=lambda wc: 1 if stage_config("depth")["backend"] == "colmap" else 0,
    params:
        depth=lambda wc: registration_depth_config(),
        centre=lambda wc: centre(wc.dataset),
        views_dir=lambda wc: res(wc.dataset, "views"),
        model_dir=lambda wc: res(wc.dataset, "reg_a", "model"),
    script:
        "../scripts/depth.py"


rule depth_view:
    input:
        unpack(depth_view_inputs),
    output:
        depth="results/{dataset}/depth/views/{cam}/{view}.npy",
        preview="results/{dataset}/depth/views/{cam}/{view}.png",
        info="results/{dataset}/depth/views/{cam}/{view}.json",
    log:
        log_path("depth_view", "{cam}_{view}"),
    benchmark:
        bench_path("depth_view", "{cam}_{view}")
    wildcard_constraints:
        view=r"\d+_\d+",
    priority: PRIORITY["synthesis"]
    conda:
        "../envs/plenocal.yaml"
    threads: 1
    resources:
        mem_mb=3000,
        runtime=30,
    params:
        depth=lambda wc: synthesis_depth_config(),
        verify=lambda wc: {
            k: stage_config("verify")[k]
            for k in ("depth_sources_shots", "depth_sources_set")
        },
        views_dir=lambda wc: res(wc.dataset, "views"),
        n_views=lambda wc: n_views(wc.dataset),
    script:
        "../scripts/depth_view.py"
