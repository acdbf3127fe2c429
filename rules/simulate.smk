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


rule simulate:
    input:
        TRUTH,
        calib="data/{dataset}/calib.xml",
    output:
        "data/{dataset}/lenslet/{cam}.png",
    log:
        log_path("simulate", "{cam}"),
    benchmark:
        bench_path("simulate", "{cam}")
    wildcard_constraints:
        dataset=SYN,
    conda:
        "../envs/plenocal.yaml"
    threads: 1
    resources:
        mem_mb=3000,
        runtime=30,
    params:
        sim=sim_config,
    script:
        "../scripts/simulate.py"


rule ground_truth_cam:
    input:
        TRUTH,
        calib="data/{dataset}/calib.xml",
        setup="results/{dataset}/views/convert_setup.json",
    output:
        "results/{dataset}/ground_truth/cams/{cam}.json",
    log:
        log_path("ground_truth_cam", "{cam}"),
    benchmark:
        bench_path("ground_truth_cam", "{cam}")
    wildcard_constraints:
        dataset=SYN,
    conda:
        "../envs/plenocal.yaml"
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    params:
        convert=view_geometry,
        views=lambda wc: n_views(wc.dataset),
    script:
        "../scripts/ground_truth_cam.py"


rule ground_truth:
    input:
        lambda wc: expand(
            "results/{{dataset}}/ground_truth/cams/{cam}.json", cam=cams(wc.dataset)
        ),
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
        mem_mb=500,
        runtime=5,
    script:
        "../scripts/ground_truth.py"


rule ground_truth_render:
    input:
        TRUTH,
        cams="results/{dataset}/ground_truth/cams/{cam}.json",
    output:
        image="results/{dataset}/ground_truth/renders/{cam}/{view}.png",
        depth="results/{dataset}/ground_truth/depth/{cam}/{view}.npy",
    log:
        log_path("ground_truth_render", "{cam}_{view}"),
    benchmark:
        bench_path("ground_truth_render", "{cam}_{view}")
    wildcard_constraints:
        dataset=SYN,
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


TARGETS.append(simulate_targets)
