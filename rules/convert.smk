"""Lenslet-to-multiview conversion (RLC, Fig. 1 (a)), SHOTS_PER_JOB shots a job: rules
convert_<k> measure each image (analysis.npz) and render its central view - all that
registration A needs - with the patch-size map and disparity.json; rules
convert_views_<k> render the other views from the measurements, beside registration A
(issue 15: measuring is 0.64 of a shot's 1.0 s of conversion, and a job's start-up 0.3 s).
On synthetic datasets also the views' quality against the simulator's ideal renders (rule
convert_quality).

Snakemake outputs cannot be functions of the wildcards, and each shot's files are declared
as outputs, so the rules are defined per dataset (whose shots and N they know): convert_<k>
for the first, convert_<i>_<k> for the i-th other (common.smk chunk_rule); their files
are named in full (common.smk dataset_path). Rules convert_views_<k> declare each shot's
views.json, which the consumers read, and only those of its views that are not on disk
(common.smk missing_views: the no-op's DAG).

A real capture's shot given as a video (plenocal.io.lenslet) is converted from the frame
rule lenslet_frame extracts into results/<d>/lenslet/<shot>.png (common.smk
lenslet_image), 16-bit with 16 significant bits whatever convert.bit_depth says (8-bit
from an 8-bit recording; the
`video_frames` of the conversions' convert params, only where a job has such a shot: the
other jobs' params are as they were)."""


rule lenslet_frame:
    input:
        video=lenslet_frame_input,
    output:
        lenslet="results/{dataset}/lenslet/{cam}.png",
    log:
        log_path("lenslet_frame", "{cam}"),
    benchmark:
        bench_path("lenslet_frame", "{cam}")
    wildcard_constraints:
        dataset=VIDEO,
        cam=VIDEO_SHOTS,
    priority: PRIORITY["chain"]
    conda:
        "../envs/plenocal.yaml"
    threads: 1
    resources:
        mem_mb=1500,
        runtime=5,
    params:
        video=lenslet_frame_params,
        capture=lambda wc: capture_fingerprints(wc.dataset, [wc.cam]),
    script:
        "../scripts/lenslet_frame.py"


rule convert_setup:
    input:
        lenslet=lambda wc: lenslet_image(wc.dataset, full_set_cam(wc.dataset)),
        calib="data/{dataset}/calib.xml",
        camera="data/{dataset}/camera.yaml",
    output:
        setup="results/{dataset}/views/convert_setup.json",
    log:
        log_path("convert_setup"),
    benchmark:
        bench_path("convert_setup")
    priority: PRIORITY["chain"]
    conda:
        "../envs/plenocal.yaml"
    threads: 1
    resources:
        mem_mb=2500,
        runtime=10,
    params:
        convert=lambda wc: convert_settings(
            wc.dataset, setup=True, shots=[full_set_cam(wc.dataset)]
        ),
        views=lambda wc: n_views(wc.dataset),
        capture=lambda wc: capture_fingerprints(wc.dataset, [full_set_cam(wc.dataset)]),
    script:
        "../scripts/convert_setup.py"


for _i, _d in enumerate(DATASETS):
    for _k, _chunk in enumerate(shot_chunks(cams(_d))):

        rule:
            name:
                chunk_rule("convert", _i, _k)
            input:
                lenslet=[lenslet_image(_d, c) for c in _chunk],
                calib=data(_d, "calib.xml"),
                camera=data(_d, "camera.yaml"),
                setup=res(_d, "views", "convert_setup.json"),
            output:
                centre=[res(_d, "views", c, f"{centre(_d)}.png") for c in _chunk],
                analysis=[res(_d, "views", c, "analysis.npz") for c in _chunk],
                patch_size=[res(_d, "views", c, "patch_size.npy") for c in _chunk],
                patch_png=[
                    report(
                        res(_d, "views", c, "patch_size.png"),
                        caption="../report/patch_size.rst",
                        category="Conversion",
                        subcategory=c,
                    )
                    for c in _chunk
                ],
                disparity=[res(_d, "views", c, "disparity.json") for c in _chunk],
            log:
                dataset_path(_d, log_path("convert", f"{_d}_{chunk_label(_chunk)}")),
            benchmark:
                dataset_path(_d, bench_path("convert", f"{_d}_{chunk_label(_chunk)}"))
            priority: PRIORITY["chain"]
            conda:
                "../envs/plenocal.yaml"
            threads: 1
            resources:
                mem_mb=2500,
                runtime=20,
            params:
                **capture_params(_d, _chunk),
                convert=convert_settings(_d, shots=_chunk),
                views=n_views(_d),
                centre=centre(_d),
                cams=_chunk,
            script:
                "../scripts/convert.py"

        # the other views of the same shots, after registration A's inputs
        # (PRIORITY["views"]): on the core its one-core chain leaves free
        rule:
            name:
                chunk_rule("convert_views", _i, _k)
            input:
                lenslet=[lenslet_image(_d, c) for c in _chunk],
                analysis=[res(_d, "views", c, "analysis.npz") for c in _chunk],
                # listed with the others in each shot's views.json
                centre=[res(_d, "views", c, f"{centre(_d)}.png") for c in _chunk],
                calib=data(_d, "calib.xml"),
                camera=data(_d, "camera.yaml"),
                setup=res(_d, "views", "convert_setup.json"),
            output:
                # only those not on disk: the consumers read views.json (missing_views)
                views=missing_views(_d, _chunk),
                view_set=[view_set(_d, c) for c in _chunk],
            log:
                dataset_path(
                    _d, log_path("convert_views", f"{_d}_{chunk_label(_chunk)}")
                ),
            benchmark:
                dataset_path(
                    _d, bench_path("convert_views", f"{_d}_{chunk_label(_chunk)}")
                )
            priority: PRIORITY["views"]
            conda:
                "../envs/plenocal.yaml"
            threads: 1
            resources:
                mem_mb=2500,
                runtime=20,
            params:
                **capture_params(_d, _chunk),
                convert=convert_settings(_d, shots=_chunk),
                views=n_views(_d),
                cams=_chunk,
                names=[v for v in views(_d) if v != centre(_d)],
                all_names=views(_d),
            script:
                "../scripts/convert_views.py"


rule convert_quality:
    input:
        truth=convert_quality_truth,
        converted=convert_quality_views,
        setup="results/{dataset}/views/convert_setup.json",
    output:
        quality=report(
            "results/{dataset}/convert/quality.json",
            caption="../report/convert_quality.rst",
            category="Conversion",
        ),
    log:
        log_path("convert_quality"),
    benchmark:
        bench_path("convert_quality")
    wildcard_constraints:
        dataset=SYN,
    conda:
        "../envs/plenocal.yaml"
    threads: 1
    resources:
        mem_mb=1500,
        runtime=10,
    params:
        central=lambda wc: centre(wc.dataset),
        views_dir=lambda wc: res(wc.dataset, "views"),
    script:
        "../scripts/convert_quality.py"


TARGETS.append(convert_targets)
