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
            TRUTH,
            calib="data/{dataset}/calib.xml",
        output:
            [f"data/{{dataset}}/lenslet/{c}.png" for c in cams(_d)],
        log:
            log_path("simulate"),
        benchmark:
            bench_path("simulate")
        wildcard_constraints:
            dataset=re.escape(_d),
        priority: PRIORITY["chain"]
        conda:
            "../envs/plenocal.yaml"
        threads: 16
        resources:
            mem_mb=3000,
            runtime=60,
        params:
            sim=sim_config,
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
# ground_truth_render. One rule per distinct N, as rule convert.
for _i, (_n, _datasets) in enumerate(convert_groups()):
    _syn = [d for d in _datasets if is_synthetic(d)]
    _set = [v for v in view_names(_n) if v != central_view(_n)]
    if not _syn or not _set:
        continue
    _name = "ground_truth_render_set" if _i == 0 else f"ground_truth_render_set_n{_n}"

    rule:
        name:
            _name
        input:
            TRUTH,
            cams="results/{dataset}/ground_truth/cameras.json",
        output:
            image=[
                f"results/{{dataset}}/ground_truth/renders/{{cam}}/{v}.png"
                for v in _set
            ],
            depth=[
                f"results/{{dataset}}/ground_truth/depth/{{cam}}/{v}.npy" for v in _set
            ],
        log:
            log_path("ground_truth_render_set", "{cam}"),
        benchmark:
            bench_path("ground_truth_render_set", "{cam}")
        wildcard_constraints:
            dataset="|".join(re.escape(d) for d in _syn),
            cam="|".join(sorted({re.escape(full_set_cam(d)) for d in _syn})),
        priority: PRIORITY["synthesis"]
        conda:
            "../envs/plenocal.yaml"
        threads: 1
        resources:
            mem_mb=1000,
            runtime=30,
        params:
            supersample=lambda wc: sim_config(wc)["render"]["ideal_supersample"],
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
            TRUTH,
            cams="results/{dataset}/ground_truth/cameras.json",
        output:
            image=[
                f"results/{{dataset}}/ground_truth/renders/{c}/{v}.png"
                for c, v in _keys
            ],
            depth=[
                f"results/{{dataset}}/ground_truth/depth/{c}/{v}.npy" for c, v in _keys
            ],
        log:
            log_path("ground_truth_render_central"),
        benchmark:
            bench_path("ground_truth_render_central")
        wildcard_constraints:
            dataset=re.escape(_d),
        priority: PRIORITY["synthesis"]
        conda:
            "../envs/plenocal.yaml"
        threads: 1
        resources:
            mem_mb=1000,
            runtime=30,
        params:
            supersample=lambda wc: sim_config(wc)["render"]["ideal_supersample"],
        script:
            "../scripts/ground_truth_render.py"

    workflow.ruleorder(_name, "ground_truth_render")


TARGETS.append(simulate_targets)
