"""Simulator and ground truth (synthetic datasets only): DESIGN.md "The simulator"."""


rule simulate_setup:
    output:
        scene=TRUTH[0],
        shots=TRUTH[1],
        optics=TRUTH[2],
        calib="data/{dataset}/calib.xml",
        camera="data/{dataset}/camera.yaml",
    log:
        log_path("simulate_setup"),
    benchmark:
        bench_path("simulate_setup")
    wildcard_constraints:
        dataset=SYN,
    conda:
        "../envs/plenocal.yaml"
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    params:
        sim=setup_config,
    script:
        "../scripts/simulate_setup.py"


# Every lenslet image of a dataset in one job, traced on the job's threads (numba): the
# scene, the optics and the lens maps are set up once (about 1.3 s a job when each shot
# had its own, 28 jobs on the default data), and the pixels are traced independently, so
# the images are the same bits on any number of threads. A local run gives the job the
# cores it has (at most `threads`); profiles/slurm sets what a cluster node has.
for _i, _d in enumerate(SYNTHETIC):

    rule:
        name:
            "simulate" if _i == 0 else f"simulate_{_i}"
        input:
            [dataset_path(_d, p) for p in TRUTH],
            calib=data(_d, "calib.xml"),
        output:
            [data(_d, "lenslet", f"{c}.png") for c in cams(_d)],
        log:
            dataset_path(_d, log_path("simulate")),
        benchmark:
            dataset_path(_d, bench_path("simulate"))
        priority: PRIORITY["chain"]
        conda:
            "../envs/plenocal.yaml"
        threads: 16
        resources:
            mem_mb=3000,
            runtime=60,
        params:
            sim=lenslet_sim_config(_d),
        script:
            "../scripts/simulate.py"


rule ground_truth:
    input:
        TRUTH,
        calib="data/{dataset}/calib.xml",
        setup="results/{dataset}/views/convert_setup.json",
    output:
        "results/{dataset}/ground_truth/cameras.json",
    log:
        log_path("ground_truth"),
    benchmark:
        bench_path("ground_truth")
    wildcard_constraints:
        dataset=SYN,
    conda:
        "../envs/plenocal.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    params:
        convert=view_geometry,
        views=lambda wc: n_views(wc.dataset),
        cams=lambda wc: cams(wc.dataset),
    script:
        "../scripts/ground_truth.py"


rule ground_truth_render:
    input:
        TRUTH,
        cams="results/{dataset}/ground_truth/cameras.json",
    output:
        image="results/{dataset}/ground_truth/renders/{cam}/{view}.png",
        depth="results/{dataset}/ground_truth/depth/{cam}/{view}.npy",
    log:
        log_path("ground_truth_render", "{cam}_{view}"),
    benchmark:
        bench_path("ground_truth_render", "{cam}_{view}")
    wildcard_constraints:
        dataset=SYN,
    priority: PRIORITY["synthesis"]
    conda:
        "../envs/plenocal.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    params:
        supersample=lambda wc: sim_config(wc)["render"]["ideal_supersample"],
    script:
        "../scripts/ground_truth_render.py"


# The other views of the full-set shot (the middle array shot, whose complete N x N set
# of ideal renders is a target) in one job: the scene's textures are loaded once, and
# N^2 - 2 job start-ups (about 2 s each) are saved. The central view of every shot has
# a job of its own below; other single views (Exp. 3's lateral views) stay with
# ground_truth_render. One rule per dataset, its files named in full (common.smk
# dataset_path).
for _i, _d in enumerate(SYNTHETIC):
    _full = full_set_cam(_d)
    _set = [v for v in views(_d) if v != centre(_d)]
    _name = "ground_truth_render_set" if _i == 0 else f"ground_truth_render_set_{_i}"

    rule:
        name:
            _name
        input:
            [dataset_path(_d, p) for p in TRUTH],
            cams=res(_d, "ground_truth", "cameras.json"),
        output:
            image=[res(_d, "ground_truth", "renders", _full, f"{v}.png") for v in _set],
            depth=[res(_d, "ground_truth", "depth", _full, f"{v}.npy") for v in _set],
        log:
            dataset_path(_d, log_path("ground_truth_render_set", _full)),
        benchmark:
            dataset_path(_d, bench_path("ground_truth_render_set", _full))
        priority: PRIORITY["synthesis"]
        conda:
            "../envs/plenocal.yaml"
        threads: 1
        resources:
            mem_mb=1000,
            runtime=30,
        params:
            supersample=ds_config(_d)["simulate"]["render"]["ideal_supersample"],
        script:
            "../scripts/ground_truth_render.py"

    workflow.ruleorder(_name, "ground_truth_render")


# The central view of every shot (the ideal renders the converted views are compared
# with, rule convert_quality) in one job per dataset: each single-view job was about 1.2 s
# of start-up and texture loading for 0.4 s of rendering (28 jobs on the default data).
for _i, _d in enumerate(SYNTHETIC):
    _keys = [(c, centre(_d)) for c in cams(_d)]
    _name = (
        "ground_truth_render_central"
        if _i == 0
        else f"ground_truth_render_central_{_i}"
    )

    rule:
        name:
            _name
        input:
            [dataset_path(_d, p) for p in TRUTH],
            cams=res(_d, "ground_truth", "cameras.json"),
        output:
            image=[res(_d, "ground_truth", "renders", c, f"{v}.png") for c, v in _keys],
            depth=[res(_d, "ground_truth", "depth", c, f"{v}.npy") for c, v in _keys],
        log:
            dataset_path(_d, log_path("ground_truth_render_central")),
        benchmark:
            dataset_path(_d, bench_path("ground_truth_render_central"))
        priority: PRIORITY["synthesis"]
        conda:
            "../envs/plenocal.yaml"
        threads: 1
        resources:
            mem_mb=1000,
            runtime=30,
        params:
            supersample=ds_config(_d)["simulate"]["render"]["ideal_supersample"],
        script:
            "../scripts/ground_truth_render.py"

    workflow.ruleorder(_name, "ground_truth_render")


TARGETS.append(simulate_targets)
