"""Depth of the central view of every shot in registration A (central views of the
nearest shots, SfM units; rule depth_a) and in registration B (views of its own set,
metres; rule depth_b), the inputs of the scale (Eq. 5) - plenocal.depth.shot.

A's maps are checked against each other (each against its nearest source's), so they are
made together: one job for the shots the scale reads (config scale.shots), one for the
others (the hand-held shots by default, which only the report shows: rule
depth_a_other, run last); a second dataset's rules carry its index (depth_a_1, ...).
B's maps are made DEPTH_B_SHOTS_PER_JOB shots a job (depth_b_0, depth_b_1, ...,
depth_b_other_0), on the core that A's one-core job leaves free; each job's inputs are its
shots' views.json, not their N x N views (Snakemake looks every input up and checksums a
job's inputs again for each of its outputs: 525 views x 63 outputs took 7.5 s in the
scheduler when one job declared them all)."""

for _i, _d in enumerate(DATASETS):
    for _sfx, _shots, _prio in depth_groups(_d):
        _name = f"{_sfx}" if _i == 0 else f"{_sfx}_{_i}"

        rule:
            name:
                f"depth_a{_name}"
            input:
                reg_a=res(_d, "reg_a", "reg_a.json"),
                views=[res(_d, "views", c, f"{centre(_d)}.png") for c in cams(_d)],
            output:
                depth=[res(_d, "depth", "a", f"{c}.npy") for c in _shots],
                preview=[
                    report(
                        res(_d, "depth", "a", f"{c}.png"),
                        caption="../report/depth.rst",
                        category="Depth",
                        subcategory="registration a",
                    )
                    for c in _shots
                ],
                info=[res(_d, "depth", "a", f"{c}.json") for c in _shots],
            log:
                dataset_path(_d, log_path(f"depth_a{_sfx}")),
            benchmark:
                dataset_path(_d, bench_path(f"depth_a{_sfx}"))
            priority: _prio
            conda:
                "../envs/plenocal.yaml"
            # one core: with two, the job waited for both cores to be free at once and the
            # full run's chain behind it stood still for 300 s (issue 15); given more
            # (--set-threads depth_a=2, a cluster node's cores) it sweeps a map per
            # process, the same maps
            threads: 1
            resources:
                mem_mb=3000,
                runtime=60,
                # COLMAP's patch-match stereo needs a GPU node; the plane sweep does not
                gpu=gpus("depth", "backend"),
            params:
                depth=lambda wc: registration_depth_config(),
                registration="a",
                cams=_shots,
                centre=centre(_d),
                views_dir=lambda wc, d=_d: res(d, "views"),
                model_dir=lambda wc, d=_d: res(d, "reg_a", "model"),
            script:
                "../scripts/depth.py"

        for _k, _chunk in enumerate(shot_chunks(_shots, DEPTH_B_SHOTS_PER_JOB)):

            rule:
                name:
                    chunk_rule(f"depth_b{_sfx}", _i, _k)
                input:
                    rig=res(_d, "reg_b", "rig.json"),
                    view_sets=[view_set(_d, c) for c in _chunk],
                output:
                    depth=[res(_d, "depth", "b", f"{c}.npy") for c in _chunk],
                    preview=[
                        report(
                            res(_d, "depth", "b", f"{c}.png"),
                            caption="../report/depth.rst",
                            category="Depth",
                            subcategory="registration b",
                        )
                        for c in _chunk
                    ],
                    info=[res(_d, "depth", "b", f"{c}.json") for c in _chunk],
                log:
                    dataset_path(_d, log_path("depth_b", chunk_label(_chunk))),
                benchmark:
                    dataset_path(_d, bench_path("depth_b", chunk_label(_chunk)))
                priority: _prio
                conda:
                    "../envs/plenocal.yaml"
                threads: 1
                resources:
                    mem_mb=3000,
                    runtime=30,
                    gpu=gpus("depth", "backend"),
                params:
                    depth=lambda wc: registration_depth_config(),
                    registration="b",
                    cams=_chunk,
                    centre=centre(_d),
                    views_dir=lambda wc, d=_d: res(d, "views"),
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
        view=names.VIEW_PATTERN,
    priority: PRIORITY["synthesis"]
    conda:
        "../envs/plenocal.yaml"
    threads: 1
    resources:
        mem_mb=3000,
        runtime=30,
    params:
        **depth_view_params("complete"),
    script:
        "../scripts/depth_view.py"


# On synthetic data with verify.ground_truth_own_depth, the same depth maps estimated with
# the ground-truth cameras: the synthesis scores those cameras on depth made with them, not
# on depth fitted to the complete calibration's geometry (with depth_view's maps for both,
# a calibration rotated 0.15 deg read 2.2 dB better than the truth)
use rule depth_view as depth_view_truth with:
    input:
        unpack(depth_view_truth_inputs),
    output:
        depth="results/{dataset}/depth/views_truth/{cam}/{view}.npy",
        preview="results/{dataset}/depth/views_truth/{cam}/{view}.png",
        info="results/{dataset}/depth/views_truth/{cam}/{view}.json",
    log:
        log_path("depth_view_truth", "{cam}_{view}"),
    benchmark:
        bench_path("depth_view_truth", "{cam}_{view}")
    params:
        **depth_view_params("ground_truth"),
