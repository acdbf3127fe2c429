"""Depth of the central view of every shot in registration A (central views of the
nearest shots, SfM units) and in registration B (views of its own set, metres)."""


wildcard_constraints:
    reg="a|b",


rule depth:
    input:
        unpack(depth_inputs),
    output:
        depth="results/{dataset}/depth/{reg}/{cam}.npy",
        preview="results/{dataset}/depth/{reg}/{cam}.png",
        info="results/{dataset}/depth/{reg}/{cam}.json",
    log:
        log_path("depth", "{reg}_{cam}"),
    benchmark:
        bench_path("depth", "{reg}_{cam}")
    conda:
        "../envs/plenocal.yaml"
    threads: 1
    resources:
        mem_mb=3000,
        runtime=30,
        # COLMAP's patch-match stereo needs a GPU node; the plane sweep does not
        gpu=lambda wc: 1 if stage_config("depth")["backend"] == "colmap" else 0,
    params:
        depth=lambda wc: stage_config("depth"),
        centre=lambda wc: centre(wc.dataset),
        views_dir=lambda wc: res(wc.dataset, "views"),
        model_dir=lambda wc: res(wc.dataset, "reg_a", "model"),
    script:
        "../scripts/depth.py"
