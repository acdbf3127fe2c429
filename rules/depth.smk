"""Depth of the central view of every shot in registration A (central views of the
nearest shots, SfM units) and in registration B (views of its own set, metres)."""


wildcard_constraints:
    reg="a|b",


# depth settings of the synthesis depth maps only (rule depth_view)
SYNTHESIS_DEPTH_KEYS = ("synthesis_method", "views", "sgm")


def registration_depth_config():
    """The depth settings the registrations' depth maps read: a change to the synthesis
    depth maps' settings does not rerun them (nor the scale and merge)."""
    return {
        k: v for k, v in stage_config("depth").items() if k not in SYNTHESIS_DEPTH_KEYS
    }


def synthesis_depth_config():
    """The depth settings of rule depth_view: its method's (the plane-sweep ones only
    when it is the plane sweep) and the bounds."""
    cfg = stage_config("depth")
    if cfg["synthesis_method"] == "planesweep":
        return {k: v for k, v in cfg.items() if k not in ("views", "sgm")}
    return {k: cfg[k] for k in ("synthesis_method", "sgm", "bounds_margin")}


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
        depth=lambda wc: registration_depth_config(),
        centre=lambda wc: centre(wc.dataset),
        views_dir=lambda wc: res(wc.dataset, "views"),
        model_dir=lambda wc: res(wc.dataset, "reg_a", "model"),
    script:
        "../scripts/depth.py"


# --- depth maps for view synthesis and the MPEG exports --------------------------------


def synthesis_layout(dataset):
    from plenocal.synthesis import layout_from_cams

    return layout_from_cams(array_cams(dataset), n_views(dataset))


def experiment_views(dataset, exp):
    """The views whose depth maps experiment ``exp`` reads."""
    from plenocal.synthesis import experiment_input_views

    return experiment_input_views(
        synthesis_layout(dataset), exp, stage_config("verify")["exp2_sets"]
    )


def depth_view_keys(dataset):
    """Views with a depth map for synthesis and the MPEG exports (depth.views)."""
    if stage_config("depth")["views"] == "all":
        return [f"{c}/{v}" for c in cams(dataset) for v in views(dataset)]
    keys = [k for e in (1, 2, 3) for k in experiment_views(dataset, e)]
    return list(dict.fromkeys(keys))


def depth_view_path(dataset, key, ext="npy"):
    cam, view = key.split("/")
    return res(dataset, "depth", "views", cam, f"{view}.{ext}")


def depth_view_inputs(wildcards):
    d = wildcards.dataset
    return {
        "calibration": res(d, "calibration", "cameras.json"),
        "rig": res(d, "reg_b", "rig.json"),
        # candidate sources: the same view of every array shot, every view of its set
        "views": sorted(
            {res(d, "views", c, f"{wildcards.view}.png") for c in array_cams(d)}
            | {res(d, "views", wildcards.cam, f"{v}.png") for v in views(d)}
        ),
    }


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
