"""Scale between the registrations (Eq. 5) and their merge (Eq. 6) into the complete
calibration, written in every export format."""


def scale_shots(dataset):
    """Shots whose central-view depth maps give the scale (config scale.shots)."""
    return (
        cams(dataset)
        if stage_config("scale")["shots"] == "all"
        else array_cams(dataset)
    )


rule scale:
    input:
        depth_a=lambda wc: [
            res(wc.dataset, "depth", "a", f"{c}.npy") for c in scale_shots(wc.dataset)
        ],
        depth_b=lambda wc: [
            res(wc.dataset, "depth", "b", f"{c}.npy") for c in scale_shots(wc.dataset)
        ],
    output:
        scale="results/{dataset}/merge/scale.json",
    log:
        log_path("scale"),
    benchmark:
        bench_path("scale")
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
        plain="results/{dataset}/calibration/cameras.json",
        mpeg="results/{dataset}/calibration/mpeg/cameras.json",
        colmap=directory("results/{dataset}/calibration/colmap"),
    log:
        log_path("merge"),
    benchmark:
        bench_path("merge")
    threads: 1
    resources:
        mem_mb=1000,
        runtime=5,
    params:
        shots=lambda wc: cams(wc.dataset),
    script:
        "../scripts/merge.py"


def merge_targets(dataset):
    return [
        res(dataset, "merge", "scale.json"),
        res(dataset, "calibration", "cameras.json"),
        res(dataset, "calibration", "mpeg", "cameras.json"),
        res(dataset, "calibration", "colmap"),
    ]


TARGETS.append(merge_targets)
