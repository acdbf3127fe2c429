"""Helpers shared by all the rule files - config validation, the shot and view lists,
paths, and per-stage config slices (passed as ``params`` so that a change of one
stage's settings reruns that stage and what depends on it, nothing else)."""

import base64
import json
import os
import re
from pathlib import Path

from plenocal.config import ConfigError, canonicalize, validate_config
from plenocal.calib.reg_b.datasheet import (
    DatasheetError,
    check_micro_image_pitch,
    load_datasheet,
)
from plenocal.io.lenslet import (
    CaptureError,
    VideoShot,
    check_capture,
    check_simulated_folder,
    fingerprint,
    scan_lenslet_folder,
)
from plenocal.io.raytrix import CalibError, read_calib
from plenocal.io.yamlfile import DuplicateKeyError, check_unique_keys
from plenocal import job_memory, names
from plenocal.artifacts import tracks as tracks_artifact
from plenocal.names import central_view, view_names
from plenocal.report.exports import EXPORTS

# COLMAP's logging (glog) to standard error alone, which every job's script sends to its
# rule's log (plenocal.rulelog), instead of also into *.INFO / *.WARNING files of its own
# in $TMPDIR after every job: glog reads this when pycolmap loads, in the jobs, which
# inherit this process's environment (on a cluster node too: the job's Snakemake parses
# this file again)
os.environ.setdefault("GLOG_logtostderr", "1")

try:
    # a key given twice in config.yaml (or a --configfile) is refused: Snakemake's loader
    # keeps the last one without a word (two frames named for one video shot, two views)
    check_unique_keys(workflow.configfiles)
    validate_config(config, Path(workflow.basedir) / "config.schema.yaml")
except (ConfigError, DuplicateKeyError) as err:
    raise ValueError(str(err)) from None
# every config slice the rules get as params in one key order (reordering config.yaml reruns nothing)
canonicalize(config)

DATASETS = sorted(config["datasets"])
SYNTHETIC = [d for d in DATASETS if "simulate" in config["datasets"][d]]


#: Scheduling priorities (Snakemake runs the ready job of highest priority first). The
#: longest chain of the full run is simulate -> convert -> registration A (whose poses
#: choose the pairs of all views to match) and view_features -> view_matches ->
#: baseline_sfm -> the naive calibration's reprojection -> report: these jobs go first
#: ("chain"), so that the two serial COLMAP jobs (matching, then the naive mapper) start as
#: soon as they can. Next the views other than the central ones (convert_views_<k>) and
#: their SIFT ("views"), which view_matches waits for: rendered on the core that
#: registration A's one-core chain leaves free. Then the calibration's depth maps, scale
#: and merge ("calibration"), which fill the other core beside the COLMAP jobs (before
#: them, they held view_matches back by 20 s in the full run; in the calibration alone
#: the views are done when registration A is, and nothing else waits). The lenslet
#: images (one job on every core) come first of all, then the converter's set-up, which
#: every conversion waits for. Then the synthesis (its depth maps, the ideal renders it
#: compares with, the experiments: Exp. 3 is the longest job of the tail), and last the
#: other Table I rows and the hand-held shots' depth maps, which only feed short jobs
#: (issue 15).
PRIORITY = {"synthesis": 5, "calibration": 16, "views": 18, "chain": 20}


def reprojection_priority(wildcards):
    """The naive baseline's Table I row closes the critical chain; the others do not."""
    return PRIORITY["chain"] if wildcards.calib == "baseline_sfm" else 0


def ds_config(dataset):
    return config["datasets"][dataset]


def is_synthetic(dataset):
    return dataset in SYNTHETIC


def array_cams(dataset):
    """Array shots x{col:02d}_y{row:02d}, row-major."""
    sim = ds_config(dataset).get("simulate")
    if sim is not None:
        a = sim["array"]
        return names.array_shots(a["cols"], a["rows"])
    return [c for c in real_cams(dataset) if names.is_array_shot(c)]


def hand_cams(dataset):
    sim = ds_config(dataset).get("simulate")
    if sim is not None:
        return names.handheld_shots(sim["handheld"]["count"])
    return [c for c in real_cams(dataset) if names.is_handheld_shot(c)]


def real_cams(dataset):
    """The shots of a real capture: the files in data/<dataset>/lenslet/, each a lenslet
    image named x<col>_y<row>.png or hand<k>.png, or a raw YUV recording of the shot
    (plenocal.io.lenslet; hidden files, such as a file manager's .DS_Store, are
    skipped)."""
    return list(lenslet_sources(dataset))


#: {dataset: {shot: its PNG, or its plenocal.io.lenslet.VideoShot}}, read once a run
_LENSLET_SOURCES = {}


def _scan_lenslet(dataset, sensor_size=None):
    try:
        return scan_lenslet_folder(
            Path("data") / dataset / "lenslet",
            dataset,
            ds_config(dataset).get("video"),
            sensor_size,
        )
    except CaptureError as err:
        raise ValueError(str(err)) from None


def lenslet_sources(dataset):
    """{shot: data/<d>/lenslet/<shot>.png, or the VideoShot of its recording} of a real
    capture, checked (check_real_dataset: before any job)."""
    if dataset not in _LENSLET_SOURCES:
        _LENSLET_SOURCES[dataset] = _scan_lenslet(dataset)
    return _LENSLET_SOURCES[dataset]


def video_shots(dataset):
    """The shots given as a video (whose frame rule lenslet_frame extracts)."""
    if is_synthetic(dataset):
        return []
    return [
        c for c, src in lenslet_sources(dataset).items() if isinstance(src, VideoShot)
    ]


def lenslet_image(dataset, cam):
    """The lenslet image the conversion reads: data/<d>/lenslet/<cam>.png (the
    simulator's, or a real capture's PNG), or for a shot given as a video the frame that
    rule lenslet_frame extracts, results/<d>/lenslet/<cam>.png."""
    if cam in video_shots(dataset):
        return res(dataset, "lenslet", f"{cam}.png")
    return data(dataset, "lenslet", f"{cam}.png")


def written_by_simulator(path):
    """Whether Snakemake's record of the job that wrote ``path`` (its metadata under
    .snakemake/, named as Snakemake names it: the path's URL-safe base64; kept until the
    folder is cleaned) names simulate_setup, the rule: then
    it is a simulated dataset whose truth/ was deleted, made again, not a capture."""
    record = Path(
        ".snakemake", "metadata", base64.urlsafe_b64encode(str(path).encode()).decode()
    )
    try:
        return json.loads(record.read_text()).get("rule") == "simulate_setup"
    except (OSError, ValueError, AttributeError):
        return False


def check_real_dataset(dataset):
    """A real capture's files, checked before any job: the lenslet folder (its shots, and
    its recordings against config datasets.<d>.video), calib.xml (parsed), and camera.yaml
    against its schema (plenocal.calib.reg_b.datasheet), which gives the size of a recording's
    frames, and against calib.xml's micro-image pitch (check_micro_image_pitch)."""
    _scan_lenslet(dataset)
    calib = Path("data") / dataset / "calib.xml"
    if not calib.is_file():
        raise ValueError(
            f"dataset {dataset!r}: {calib} does not exist; put the capture's Raytrix "
            "RayCalibData file there (README, 'Bringing a real capture')"
        )
    try:  # a few kB: a malformed or foreign file stops here, not in the first job
        diameter = read_calib(calib).diameter
    except CalibError as err:
        raise ValueError(f"dataset {dataset!r}: {err}") from None
    sheet_path = Path("data") / dataset / "camera.yaml"
    try:
        sheet = load_datasheet(sheet_path)
        check_micro_image_pitch(sheet, diameter, sheet_path, calib)
    except (DatasheetError, FileNotFoundError) as err:
        raise ValueError(f"dataset {dataset!r}: {err}") from None
    sensor = (sheet["sensor_width_px"], sheet["sensor_height_px"])
    sources = _scan_lenslet(dataset, sensor)
    try:
        check_capture(sources, dataset, Path("data") / dataset / "lenslet", sensor)
    except CaptureError as err:
        raise ValueError(str(err)) from None
    _LENSLET_SOURCES[dataset] = sources


for _d in DATASETS:
    if _d not in SYNTHETIC:
        check_real_dataset(_d)
    else:  # never over a capture's own files
        try:
            check_simulated_folder(Path("data") / _d, _d, written_by_simulator)
        except CaptureError as err:
            raise ValueError(str(err)) from None

#: the datasets with shots given as videos (rule lenslet_frame's), and those shots
VIDEO = "|".join(re.escape(d) for d in DATASETS if video_shots(d)) or "^$"
VIDEO_SHOTS = "|".join(sorted({c for d in DATASETS for c in video_shots(d)})) or "^$"


def capture_fingerprints(dataset, shots):
    """A real capture's files of ``shots`` by their fingerprints (plenocal.io.lenslet.
    fingerprint): a param of the jobs that read them, so that a shot replaced by an older
    file is converted again (Snakemake compares time stamps only). A simulated dataset's
    images are the simulator's outputs, made again by their own rules: none."""
    if is_synthetic(dataset):
        return {}
    sources = lenslet_sources(dataset)
    return {
        shot: fingerprint(
            sources[shot].path
            if isinstance(sources[shot], VideoShot)
            else sources[shot]
        )
        for shot in shots
    }


def capture_params(dataset, shots):
    """``{"capture": fingerprints}`` on a real capture, else nothing (a simulated dataset's
    conversion params stay as they were: its jobs do not rerun for the new key)."""
    prints = capture_fingerprints(dataset, shots)
    return {"capture": prints} if prints else {}


def lenslet_frame_input(wildcards):
    src = lenslet_sources(wildcards.dataset).get(wildcards.cam)
    if not isinstance(src, VideoShot):
        raise ValueError(
            f"dataset {wildcards.dataset!r}: shot {wildcards.cam} is not given as a "
            "video: its lenslet image is "
            + data(wildcards.dataset, "lenslet", f"{wildcards.cam}.png")
        )
    return str(src.path)


def lenslet_frame_params(wildcards):
    """The frame and format rule lenslet_frame reads (plenocal.io.lenslet.VideoShot)."""
    return lenslet_sources(wildcards.dataset)[wildcards.cam].params()


def cams(dataset):
    return array_cams(dataset) + hand_cams(dataset)


def n_views(dataset):
    return ds_config(dataset)["views"]


def views(dataset):
    return view_names(n_views(dataset))


def centre(dataset):
    return central_view(n_views(dataset))


def full_set_cam(dataset):
    """The shot whose complete N x N ground truth is rendered: the array's middle."""
    a = array_cams(dataset)
    return a[len(a) // 2]


def data(dataset, *parts):
    return str(Path("data", dataset, *parts))


def res(dataset, *parts):
    """results/<dataset>/<parts...> (os.path.join: the DAG calls this ~7,000 times,
    pathlib takes 3x as long)."""
    return os.path.join("results", dataset, *parts)


def warn_stale_shot_folders():
    """Name every dataset's shot folders (views/, depth/views/, ground_truth/...) that the
    config no longer names (plenocal.artifacts.stale_shots; at the start of a run that has
    jobs, not on a no-op).
    """
    from snakemake.logging import logger
    from plenocal.artifacts.stale_shots import stale_dataset_folders, stale_shot_message

    for d in DATASETS:
        stale = stale_dataset_folders(res(d), cams(d))
        if stale:
            logger.warning(stale_shot_message(d, stale))


def log_path(rule, name="{dataset}"):
    return f"results/{{dataset}}/logs/{rule}/{name}.log"


def bench_path(rule, name="{dataset}"):
    return f"results/{{dataset}}/benchmarks/{rule}/{name}.tsv"


def dataset_path(dataset, pattern):
    """``pattern`` (a path with ``{dataset}``) for one dataset. The rules made for one
    dataset name their files in full: Snakemake's index of outputs looks a path up by the
    constant part of each output before its first wildcard, and ``results/{dataset}/...``
    has only ``results/`` - every path of the run was tried against every such output
    (issue 15: the no-op's DAG)."""
    return pattern.replace("{dataset}", dataset)


def stage_config(name):
    return config[name]


def sole_target_threads(rule, threads):
    """A job's threads: ``threads``, or every core of a local run (``workflow.cores``)
    where this rule's job is the run's only target, as in the calibration alone
    (``snakemake -j2 results/<dataset>/calibration/cameras.json``): every other job of that
    run comes before it, so no job could use a core beside it, and it would otherwise run
    on one while the other idles. For rules whose outputs are the same bytes on any number
    of threads (refine's cameras: BENCHMARKS.md, "The refine job's threads: the same bytes for
    any number"). Evaluated once the run's targets are known; a cluster run keeps
    ``threads`` (its profile sets them), as does ``--set-threads``."""
    dag = workflow.dag
    if (
        dag is None
        or not workflow.local_exec
        or len(dag.targetjobs) != 1
        or next(iter(dag.targetjobs)).rule.name != rule
    ):
        return threads
    return max(threads, workflow.cores or 1)


def gpus(stage, key):
    """A rule's ``gpu`` resource: 1 where config ``<stage>.<key>`` asks for COLMAP's CUDA
    code by name (``cuda``, ``colmap``), so that a cluster sends the job to a GPU node;
    ``auto`` declares none and takes a GPU only where the job finds one (plenocal.gpu).
    """
    return lambda wc: 1 if stage_config(stage)[key] in ("cuda", "colmap") else 0


SFM_CORE = ("seed", "num_threads", "max_num_features", "sift", "device")


def sfm_params(*sections):
    """The sfm settings that one step reads - the core ones and the named sections - so a
    change to, say, the verification's matching does not rerun registration A."""
    cfg = stage_config("sfm")
    return {k: cfg[k] for k in (*SFM_CORE, *sections)}


def add_code_params():
    """Give each script's job the param ``code`` - the hash of the package's modules
    that its script imports (plenocal.codehash). Snakemake's own code trigger
    sees the script only, so a new version of the package's logic (Eq. 5, say) left the
    old outputs in place; now the params trigger reruns the jobs whose modules changed,
    and only those. Called by the Snakefile once every rule file is read."""
    from plenocal.codehash import script_code

    for r in workflow.rules:
        if r.script is not None:
            r.set_params(
                code=script_code(
                    r.basedir.join(r.script).get_path_or_uri(secret_free=True)
                )
            )


# The targets of the default target: each stage adds its final outputs once it is real.
TARGETS = []


def stage_targets():
    """Each stage's final outputs (TARGETS) for every dataset."""
    return [path for d in DATASETS for fn in TARGETS for path in fn(d)]


def final_targets():
    """The default target's inputs: each stage's final outputs (TARGETS), and, found when
    the DAG is built, every output of the run that is missing (default_run_gaps)."""
    out = stage_targets()
    return out + [lambda wildcards: default_run_gaps(out)]


# --- every output of the default run: made again where it is missing (issue 34) ---------
#
# Snakemake makes a missing file again only where a target or a job that must run asks for
# it: an intermediate whose consumers are up to date (reg_a/features.db, a depth map, a
# baseline's cameras.json) was deleted, and "Nothing to be done". Every output of every job
# of the default run (logs and benchmarks aside) is therefore listed by walking the rules
# from the stages' targets, as Snakemake's DAG does, and those missing are asked for too
# (only those: an existing file as a target costs the DAG a look-up, and the no-op its
# time, issue 15). The walk reads each rule's declared outputs and inputs, so a rule added
# later is covered without being named here.


def _fixed_outputs():
    """{path: (rl, wildcards)} of the rules whose files are named in full or by the
    dataset alone (each dataset that its constraints allow), and the rules with other
    wildcards (depth_view's cam and view, ...), which the walk matches by pattern."""
    from snakemake.io import apply_wildcards

    fixed, patterned = {}, []
    for rl in workflow.rules:
        if not rl.output:
            continue
        if not rl.wildcard_names:
            choices = [{}]
        elif rl.wildcard_names == {"dataset"}:
            choices = [{"dataset": d} for d in DATASETS]
        else:
            patterned.append(rl)
            continue
        for wc in choices:
            paths = [apply_wildcards(o, wc) for o in rl.output]
            if wc and not rl.output[0].match(paths[0]):
                continue  # a constraint (dataset=SYN) rules this dataset out
            for path in paths:
                fixed.setdefault(path, (rl, wc))
    return fixed, patterned


def default_run_outputs(targets, only=None):
    """[(path, is_directory)] of every output (logs and benchmarks aside) of the jobs that
    ``targets`` need, found as Snakemake's DAG finds them: from each file to the rule that
    makes it, and from that rule's inputs on. ``only``: the outputs of the jobs of these
    rules alone (names; rules/stages.smk), the walk the same."""
    from snakemake.io import apply_wildcards

    fixed, patterned = _fixed_outputs()
    jobs, seen, out = set(), set(), []
    todo = list(targets)
    while todo:
        path = todo.pop()
        if path in seen:
            continue
        seen.add(path)
        job = fixed.get(path)
        if job is None:
            job = next(
                (
                    (r, m.groupdict())
                    for r in patterned
                    for o in r.output
                    if (m := o.match(path))
                ),
                None,
            )
            if job is None:
                continue  # a source file (data/<d>/ of a real capture)
        rl, wc = job
        key = (rl.name, tuple(sorted(wc.items())))
        if key in jobs:
            continue
        jobs.add(key)
        if only is None or rl.name in only:
            out.extend((apply_wildcards(o, wc), o.is_directory) for o in rl.output)
        todo.extend(str(f) for f in rl.expand_input(wc)[0])
    return out


def _altered_since_written(folder):
    """Whether files were removed from (or added to) a directory output after its job:
    Snakemake touches ``.snakemake_timestamp`` in it last, so the folder's own mtime is
    newer only where its entries changed since."""
    try:
        stamp = os.stat(os.path.join(folder, ".snakemake_timestamp")).st_mtime_ns
    except FileNotFoundError:
        return False  # not written by Snakemake, or no stamp: nothing to compare
    return os.stat(folder).st_mtime_ns > stamp


def default_run_gaps(targets):
    """The outputs of the default run (default_run_outputs) that are missing: asked for,
    so that their jobs run, and after them every job that reads them. A directory output
    from which a file was removed (a COLMAP model, the MPEG exports) exists, so it cannot
    be asked for: its job is forced, as ``--forcerun <folder>`` would (Snakemake's DAG is
    being built when this runs)."""
    missing, altered = [], []
    for path, is_dir in default_run_outputs(targets):
        if not os.path.exists(path):
            missing.append(path)
        elif is_dir and _altered_since_written(path):
            altered.append(path)
    if altered:
        from snakemake.logging import logger

        logger.warning(
            "files were removed from "
            + ", ".join(altered)
            + " after the job that wrote it: its job runs again"
        )
        workflow.dag.forcefiles.update(altered)
    have = set(targets)
    return [p for p in missing if p not in have]


# --- helpers of rules/convert.smk -----------------------------------------------------


#: convert settings that only convert_setup reads: left out of the conversions' params, so
#: that a change reruns them only as the jobs after convert_setup (whose convert_setup.json
#: keeps its bytes: asked for alone, `snakemake <that file>`, nothing else reruns after it)
SETUP_ONLY_CONVERT_KEYS = ("grid_foreign",)


def convert_settings(dataset, setup=False, shots=()):
    """The convert block with the dataset's own overrides (its `mla` set-up) applied:
    only the converter of that dataset reruns when it changes. ``setup``: rule
    convert_setup's, with the keys only it reads (SETUP_ONLY_CONVERT_KEYS). ``shots``:
    the job's; those given as a video are listed in ``video_frames`` (their lenslet image
    is lenslet_frame's frame: a 16-bit one converted with 16 significant bits, which
    ``bit_depth: auto`` would not always find; an 8-bit one, from an 8-bit recording, is 8
    bits anyway), a key that only such a job's params
    have."""
    out = dict(stage_config("convert"))
    if ds_config(dataset).get("mla") is not None:
        out["mla"] = ds_config(dataset)["mla"]
    if out["tile_size"] != "auto":
        # upsample sets an automatic tile only (plenocal.convert.shot.resolve_tile): with a
        # tile given it changes no view (it reran all 59 jobs of the tiny config)
        out.pop("upsample")
    if not setup:
        for key in SETUP_ONLY_CONVERT_KEYS:
            out.pop(key, None)
    frames = [c for c in shots if c in video_shots(dataset)]
    if frames:
        out["video_frames"] = frames
    return out


def convert_quality_truth(wildcards):
    d = wildcards.dataset
    gt = Path(res(d, "ground_truth", "renders"))
    # every ideal render the ground-truth renders include: the central view of every shot
    # and the full N x N set of one shot (see rules/simulate.smk)
    out = [str(gt / c / f"{centre(d)}.png") for c in cams(d)]
    out += [str(gt / full_set_cam(d) / f"{v}.png") for v in views(d) if v != centre(d)]
    return out


def convert_quality_views(wildcards):
    """The converted views that have an ideal render: every shot's central view and the
    views.json of the shot with a full set (its other views are not in the DAG:
    missing_views)."""
    d = wildcards.dataset
    return [res(d, "views", c, f"{centre(d)}.png") for c in cams(d)] + [
        view_set(d, full_set_cam(d))
    ]


def convert_targets(dataset):
    """Per shot, one output of each conversion job (disparity.json, views.json) and the
    views that are not on disk (missing_views): the DAG matches two paths per shot
    instead of N x N + 1 (the no-op's time, issue 15), and a view deleted by hand is
    asked for again (Snakemake reruns a job for a missing output only where asked)."""
    out = [res(dataset, "views", c, "disparity.json") for c in cams(dataset)]
    out += view_sets(dataset, cams(dataset))
    # a view deleted by hand: asked for, so that its job reruns (missing_views)
    out += missing_views(dataset, cams(dataset))
    if is_synthetic(dataset):
        out.append(res(dataset, "convert", "quality.json"))
    return out


# --- jobs of several shots -------------------------------------------------------------

#: shots per job of the per-shot steps whose start-up (imports, numba's or COLMAP's set-up:
#: 1.1-1.4 s) is as long as a shot's work: rules view_features and depth_b. Snakemake
#: checksums a job's inputs under 1 MB once for each of its outputs, so a job of all shots
#: with every view as an input would cost more than it saves (depth.smk).
SHOTS_PER_JOB = 7


#: Registration B's depth maps: 6 shots a job at most, so that its jobs (about 1.1 s a
#: shot and 2 s a job) share the two cores with registration A's single job (20 s for
#: 21 maps) evenly: in 3 jobs of 7 the last ran alone for 10 s after A's (issue 15).
DEPTH_B_SHOTS_PER_JOB = 6


def shot_chunks(shots, per_job=SHOTS_PER_JOB):
    """``shots`` in order, in the fewest runs of at most ``per_job``, of even lengths
    (differing by one at most: 21 shots 6 a job are 6, 5, 5, 5)."""
    n = -(-len(shots) // per_job)
    size, extra = divmod(len(shots), max(n, 1))
    ends = [k * size + min(k, extra) for k in range(n + 1)]
    return [shots[a:b] for a, b in zip(ends, ends[1:])]


def chunk_label(chunk):
    """A run of shots in a log or benchmark file name: its first and last shot."""
    return chunk[0] if len(chunk) == 1 else f"{chunk[0]}-{chunk[-1]}"


def chunk_rule(base, dataset_index, k):
    """The name of the k-th chunk rule of ``base`` for the dataset of that index."""
    return f"{base}_{k}" if dataset_index == 0 else f"{base}_{dataset_index}_{k}"


# --- helpers of rules/depth.smk -------------------------------------------------------


def depth_groups(dataset):
    """[(rule-name suffix, shots, priority)]: the scale's shots with the calibration, the
    others last; empty groups left out."""
    scale = scale_shots(dataset)
    other = [c for c in cams(dataset) if c not in scale]
    return [
        (sfx, shots, prio)
        for sfx, shots, prio in (
            ("", scale, PRIORITY["calibration"]),
            ("_other", other, 0),
        )
        if shots
    ]


# depth settings of the synthesis depth maps only (rule depth_view)
SYNTHESIS_DEPTH_KEYS = ("synthesis_method", "views", "sgm")
# the keys only the registrations' depth maps read (depth_view leaves them out): their
# reduction, their backend with its colmap block, and their sources
REGISTRATION_DEPTH_KEYS = (
    "registration_downsample",
    "backend",
    "colmap",
    "sources_a",
    "sources_b",
)


# the keys the registrations' depth maps read by COLMAP's patch-match stereo
# (plenocal.depth.shot: the sources, the bounds, the reduction and the colmap block; none of
# the plane sweep's)
COLMAP_DEPTH_KEYS = (
    "backend",
    "sources_a",
    "sources_b",
    "bounds_margin",
    "registration_downsample",
    "colmap",
)


def registration_depth_config():
    """The depth settings the registrations' depth maps read: a change to the synthesis
    depth maps' settings does not rerun them (nor the scale and merge), nor one to the
    backend they do not use (the colmap block under the plane sweep, the plane sweep's
    keys under colmap; auto takes either where it runs, so both)."""
    cfg = {
        k: v for k, v in stage_config("depth").items() if k not in SYNTHESIS_DEPTH_KEYS
    }
    if cfg["backend"] == "planesweep":
        cfg.pop("colmap")
    elif cfg["backend"] == "colmap":
        cfg = {k: cfg[k] for k in COLMAP_DEPTH_KEYS}
    return cfg


def synthesis_depth_config():
    """The depth settings that depth_view reads - its method's (the plane-sweep ones only
    when it is the plane sweep, none of REGISTRATION_DEPTH_KEYS) and the bounds."""
    cfg = stage_config("depth")
    if cfg["synthesis_method"] == "planesweep":
        return {
            k: v
            for k, v in cfg.items()
            if k not in ("views", "sgm", *REGISTRATION_DEPTH_KEYS)
        }
    return {k: cfg[k] for k in ("synthesis_method", "sgm", "bounds_margin")}


def synthesis_layout(dataset):
    from plenocal.verify.experiments import layout_from_cams

    return layout_from_cams(array_cams(dataset), n_views(dataset))


def experiment_views(dataset, exp):
    """The views whose depth maps experiment ``exp`` reads."""
    from plenocal.verify.experiments import experiment_input_views

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
    cam, view = names.split_key(key)
    return res(dataset, "depth", "views", cam, f"{view}.{ext}")


def depth_view_params(cameras):
    """The params of scripts/depth_view.py: rule depth_view's (``complete``) and rule
    depth_view_truth's (``ground_truth``), the camera set the maps are made with."""
    return {
        "depth": lambda wc: synthesis_depth_config(),
        "verify": lambda wc: {
            k: stage_config("verify")[k]
            for k in ("depth_sources_shots", "depth_sources_set")
        },
        "views_dir": lambda wc: res(wc.dataset, "views"),
        "n_views": lambda wc: n_views(wc.dataset),
        "cameras": cameras,
    }


def depth_view_truth_path(dataset, key):
    """A view's depth map estimated with the ground-truth cameras (rule depth_view_truth)."""
    cam, view = names.split_key(key)
    return res(dataset, "depth", "views_truth", cam, f"{view}.npy")


def depth_view_truth_inputs(wildcards):
    """depth_view's inputs with the ground-truth cameras in place of the calibration."""
    return {
        **depth_view_inputs(wildcards),
        "calibration": res(wildcards.dataset, "ground_truth", "cameras.json"),
    }


def depth_view_inputs(wildcards):
    d = wildcards.dataset
    return {
        "calibration": res(d, "calibration", "cameras.json"),
        "rig": res(d, "reg_b", "rig.json"),
        # candidate sources: the same view of every array shot, every view of its set
        # (the shots' views.json: one input a shot)
        "view_sets": view_sets(d, sorted({*array_cams(d), wildcards.cam})),
    }


def view_set(dataset, cam):
    """The shot's views.json (plenocal.convert.viewset): the input of the rules that read
    all its views, instead of its N x N PNGs (issue 15: the DAG's look-ups)."""
    return res(dataset, "views", cam, "views.json")


def view_sets(dataset, shots):
    return [view_set(dataset, c) for c in shots]


def missing_views(dataset, shots):
    """The views other than the central one of ``shots`` that are not on disk: what rules
    convert_views_<k> declare as outputs, beside each shot's views.json (always). Every
    rule that reads a whole shot takes its views.json, so the PNGs already on disk need no
    place in the DAG: a no-op rerun then skips the look-ups and metadata reads of 672 of
    the default run's 1,257 outputs (issue 15: the DAG's build 0.52-0.58 -> 0.26-0.28
    s). A fresh run declares them all, and a view deleted by hand is declared again and
    asked for by the default target (convert_targets), so its job reruns
    (tests/test_workflow_rerun.py; before, when every view was an output but no rule
    asked for them, it did not)."""
    c0 = centre(dataset)
    return [
        p
        for c in shots
        for v in views(dataset)
        if v != c0 and not os.path.exists(p := res(dataset, "views", c, f"{v}.png"))
    ]


def true_depth_path(dataset, key):
    cam, view = names.split_key(key)
    return res(dataset, "ground_truth", "depth", cam, f"{view}.npy")


# --- helpers of rules/merge.smk -------------------------------------------------------


def scale_shots(dataset):
    """Shots whose central-view depth maps give the scale (config scale.shots)."""
    return (
        cams(dataset)
        if stage_config("scale")["shots"] == "all"
        else array_cams(dataset)
    )


def merge_targets(dataset):
    return [
        res(dataset, "merge", "scale.json"),
        res(dataset, "calibration", "eq6", "cameras.json"),
        res(dataset, "calibration", "eq6", "mpeg", "cameras.json"),
        res(dataset, "calibration", "eq6", "colmap"),
    ]


# --- helpers of rules/refine.smk ------------------------------------------------------


def refine_enabled():
    return bool(stage_config("refine")["enabled"])


def refine_inputs(wildcards):
    """The Eq. 6 calibration and the rig; where the refinement runs, the track sets of
    rule refine_tracks that refine.tracks names (central, views or both) and the merge's
    scale. With refine.enabled false the Eq. 6 result is copied, and the calibration waits
    for no matching."""
    d = wildcards.dataset
    out = {
        "eq6": res(d, "calibration", "eq6", "cameras.json"),
        "rig": res(d, "reg_b", "rig.json"),
    }
    # --forcerun refine, the stage's name, makes its track sets again too (as stage_outputs
    # does for a stage of several rules: evaluated before Snakemake decides what runs)
    dag = workflow.dag
    if dag is not None and any(rl.name == "refine" for rl in dag.forcerules):
        dag.forcerules.update(stage_rules("refine"))
    if refine_enabled():
        out["tracks"] = [
            res(d, "refine", "tracks", s)
            for s in tracks_artifact.SOURCES_OF[stage_config("refine")["tracks"]]
        ]
        # the merge's scale source and the stage's step (refine.scale: auto)
        out["scale"] = res(d, "merge", "scale.json")
    return out


def track_config(source):
    """The refine keys that the track set of ``source`` depends on (the params of rule
    refine_tracks); a change to the adjustments' own (the loss, the passes, the rig's and
    the focal length's modes) remakes no track set, nor one to the other source's own keys
    (SOURCE_ONLY_TRACK_KEYS)."""
    cfg = stage_config("refine")
    other = {
        k for s, keys in SOURCE_ONLY_TRACK_KEYS.items() if s != source for k in keys
    }
    return {k: cfg[k] for k in TRACK_KEYS if k in cfg and k not in other}


#: the refine: keys of :func:`track_config` (plenocal.calib.track_sets.make_track_set)
TRACK_KEYS = (
    "matches",
    "carry_every",
    "max_points",
    "max_error_px",
    "min_angle_deg",
    "align",
)
#: the TRACK_KEYS that one source's set alone reads: how the central views' points are
#: carried into the other views, and which of every view's matches are kept
SOURCE_ONLY_TRACK_KEYS = {"central": ("carry_every",), "views": ("matches",)}


def refine_config():
    """The refine block as the refine job reads it - all but its thread count (the job's
    threads: the same cameras to the bit for any number, BENCHMARKS.md, "The refine job's
    threads"), so that a change to num_threads reruns nothing."""
    return {k: v for k, v in stage_config("refine").items() if k != "num_threads"}


def refine_tracks_inputs(wildcards):
    """One track set's inputs: the Eq. 6 calibration, the rig, the matches of its source
    (central: the central views' own, from match_central; views: every view's, from
    view_matches) and, where the observations are aligned by their patches or carried
    into the other views by them, the views themselves."""
    d = wildcards.dataset
    cfg = stage_config("refine")
    db = "central.db" if wildcards.source == "central" else "database.db"
    out = {
        "eq6": res(d, "calibration", "eq6", "cameras.json"),
        "rig": res(d, "reg_b", "rig.json"),
        "database": res(d, "matches", db),
    }
    if cfg["align"]["enabled"] or wildcards.source == "central":
        out["view_sets"] = view_sets(d, cams(d))
    return out


def _bytes_of(input, keys):
    """The summed size of the job's inputs ``keys`` that exist (none before they are made:
    Snakemake works a job's resources out again when it is about to run)."""
    paths = [input[k] for k in keys if k in input.keys()]
    return sum(os.path.getsize(f) for f in paths if os.path.exists(f))


def refine_tracks_mem_mb(wildcards, input):
    """Rule refine_tracks' memory request: it grows with the match database the job reads
    (plenocal.job_memory)."""
    return job_memory.refine_tracks_mem_mb(_bytes_of(input, ("database",)))


def refine_mem_mb(wildcards, input):
    """Rule refine's memory request: it grows with the track sets the job reads
    (plenocal.job_memory)."""
    folders = [f for f in input.get("tracks", []) if os.path.isdir(f)]
    size = sum(e.stat().st_size for f in folders for e in os.scandir(f) if e.is_file())
    return job_memory.refine_mem_mb(size)


def reprojection_mem_mb(wildcards, input):
    """A Table I triangulation's memory request: it grows with the view database
    (plenocal.job_memory)."""
    return job_memory.reprojection_mem_mb(_bytes_of(input, ("database",)))


def refine_targets(dataset):
    return [
        res(dataset, "calibration", f)
        for f in ("cameras.json", "mpeg/cameras.json", "colmap", "refine.json")
    ]


def mpeg_views_inputs(wildcards):
    d = wildcards.dataset
    keys = depth_view_keys(d)
    return {
        "mpeg": res(d, "calibration", "mpeg", "cameras.json"),
        "depth": [depth_view_path(d, k) for k in keys],
        "view_sets": view_sets(d, dict.fromkeys(names.split_key(k)[0] for k in keys)),
    }


def mpeg_views_targets(dataset):
    """The MPEG depth/texture/RVS exports, where the workflow defines the rules that
    make their inputs (a workflow of rig and merge alone, as in the tests, has none)."""
    convert = chunk_rule("convert", DATASETS.index(dataset), 0)
    if not all(workflow.is_rule(r) for r in ("depth_view", convert)):
        return []
    return [res(dataset, "calibration", "mpeg", f) for f in ("depth", "texture", "rvs")]


# --- helpers of rules/stages.smk ------------------------------------------------------


#: stage -> the names of its rules (full match; <i>, the dataset's index, and <k>, the
#: job's, as common.smk's chunk_rule and depth.smk name them)
STAGE_RULES = {
    "convert": r"lenslet_frame|convert_setup|convert(_views)?(_\d+){1,2}",
    "reg_a": r"features_a|match_a|map_a|match_central",
    "reg_b": r"rig_b",
    "refine": r"refine(_tracks)?",
    "depth": r"depth_a(_other)?(_\d+)?|depth_b(_other)?(_\d+){1,2}",
    "verify": (
        r"view_features(_\d+){1,2}|view_matches|reprojection(_calib|_complete)?"
        r"|baseline_(sfm|scratch)|depth_view(_truth)?|synthesis_exp\d+(_part)?|mpeg_views"
        r"|gt_errors|convert_quality|gaussian_splatting"
    ),
    # a stage's jobs of one kind, by the name their rules share (the README's second
    # table): the name a user reads in the log as view_features_2 and types without
    # the job's number
    "convert_views": r"convert_views(_\d+){1,2}",
    "depth_b": r"depth_b(_\d+){1,2}",
    "depth_b_other": r"depth_b_other(_\d+){1,2}",
    "view_features": r"view_features(_\d+){1,2}",
}


def stage_rules(stage):
    """The rules of ``stage`` that this workflow defines, in definition order."""
    pattern = re.compile(STAGE_RULES[stage])
    return [rl for rl in workflow.rules if pattern.fullmatch(rl.name)]


def stage_outputs(wildcards, stage):
    """The input of a stage's own rule (rules/stages.smk), evaluated while Snakemake's DAG
    is built (as default_run_gaps is). Named in --until: every output of the stage's jobs
    in the default run, so that the run stops after them. Named in --forcerun: the stage's
    rules are added to those forced, and nothing is asked for (the stage's jobs run where
    the run's targets need them: the default target needs them all)."""
    dag = workflow.dag
    rules = stage_rules(stage)
    if any(rl.name == stage for rl in dag.forcerules):
        dag.forcerules.update(rules)
    if stage not in dag.untilrules:
        return []
    only = {rl.name for rl in rules}
    return [path for path, _ in default_run_outputs(stage_targets(), only=only)]


# --- helpers of rules/report.smk ------------------------------------------------------


def report_inputs(wildcards):
    """What the page shows, for the stages this workflow defines: a section whose
    producing rule is not included is reported as "not produced" instead of failing."""
    d = wildcards.dataset
    have = workflow.is_rule
    out = {}
    if have("reprojection"):
        out["reprojection"] = res(d, "eval", "reprojection.json")
    gt_rules = ("ground_truth", "map_a", "rig_b", "scale", "merge", "refine")
    if is_synthetic(d) and all(have(r) for r in gt_rules):
        out["gt_errors"] = res(d, "eval", "gt_errors.json")
    if is_synthetic(d) and have("ground_truth"):
        out["ground_truth"] = res(d, "ground_truth", "cameras.json")
    for k in (1, 2, 3):
        if have(f"synthesis_exp{k}"):
            out[f"exp{k}"] = res(d, "eval", f"synthesis_exp{k}.json")
    if have("refine"):
        out["calibration"] = res(d, "calibration", "cameras.json")
        out["refine"] = res(d, "calibration", "refine.json")
    if have("scale"):
        out["scale"] = res(d, "merge", "scale.json")
    if have("map_a"):
        out["reg_a"] = res(d, "reg_a", "reg_a.json")
    if have("rig_b"):
        out["rig"] = res(d, "reg_b", "rig.json")
    if is_synthetic(d) and have("convert_quality"):
        out["convert_quality"] = res(d, "convert", "quality.json")
    if have(chunk_rule("convert", DATASETS.index(d), 0)):
        out["patch_size"] = [res(d, "views", c, "patch_size.png") for c in cams(d)]
        # their warnings reach the report's first screen
        out["disparity"] = [res(d, "views", c, "disparity.json") for c in cams(d)]
        out["convert_setup"] = res(d, "views", "convert_setup.json")
    if have("features_a"):
        out["features"] = res(d, "reg_a", "features.json")
    if have("depth_a") and have(chunk_rule("depth_b", 0, 0)):
        out["depth"] = [
            res(d, "depth", r, f"{c}.png") for r in ("a", "b") for c in cams(d)
        ]
    # the calibration's files for other tools that this run makes, listed on the page
    made = set(optional_export_targets(d))
    out["exports"] = [
        res(d, e.rel)
        for e in EXPORTS
        if have(e.rule) and (not e.optional or res(d, e.rel) in made)
    ]
    return out


def optional_export_targets(dataset):
    """The optional exports (plenocal.report.exports.Export.optional) this run makes."""
    return mpeg_views_targets(dataset) + gaussian_splatting_targets(dataset)


def report_targets(dataset):
    return [res(dataset, "report", "index.html")]


# --- helpers of rules/reprojection.smk ------------------------------------------------


REPROJECTION_CALIB = {
    "reg_a": ("reg_a", "reg_a.json"),
    "reg_b": ("reg_b", "rig.json"),
    "complete": ("calibration", "cameras.json"),
    "eq6": ("calibration", "eq6", "cameras.json"),
    "baseline_sfm": ("baseline", "cameras.json"),
    "ground_truth": ("ground_truth", "cameras.json"),
}


def reprojection_calibs(dataset):
    out = ["reg_a", "reg_b", "complete"] + (["eq6"] if refine_enabled() else [])
    out += ["baseline_sfm"]
    return out + (["ground_truth"] if is_synthetic(dataset) else [])


def scratch_sfm_input(wildcards):
    """SfM of all views from scratch joins Table I where sfm.baseline.from_scratch."""
    if stage_config("sfm")["baseline"]["from_scratch"]:
        return [res(wildcards.dataset, "baseline", "scratch.json")]
    return []


def reprojection_targets(dataset):
    return [res(dataset, "eval", "reprojection.json")]


def gaussian_splatting_targets(dataset):
    """calibration/gaussian_splatting/ where export.gaussian_splatting asks for it in the
    default run."""
    if not stage_config("export")["gaussian_splatting"]:
        return []
    return [res(dataset, "calibration", "gaussian_splatting")]


# --- helpers of rules/rig.smk ---------------------------------------------------------


def rig_b_disparities(wildcards):
    return [
        res(wildcards.dataset, "views", c, "disparity.json")
        for c in cams(wildcards.dataset)
    ]


def rig_targets(dataset):
    return [res(dataset, "reg_b", "rig.json")]


# --- helpers of rules/sfm.smk ---------------------------------------------------------


def central_views(wildcards):
    d = wildcards.dataset
    return [res(d, "views", c, f"{centre(d)}.png") for c in cams(d)]


def sfm_targets(dataset):
    return [res(dataset, "reg_a", "reg_a.json")]


# --- helpers of rules/simulate.smk ----------------------------------------------------


SYN = "|".join(re.escape(d) for d in SYNTHETIC) or "^$"


TRUTH = [
    "data/{dataset}/truth/scene.json",
    "data/{dataset}/truth/shots.json",
    "data/{dataset}/truth/optics.json",
]


def sim_config(wildcards):
    return ds_config(wildcards.dataset)["simulate"]


def setup_config(wildcards):
    """The simulate slice without what only the lenslet renders use (rays per pixel):
    changing it re-renders the lenslet images and nothing else. The sensor's readout
    (noise, bit depth) stays: simulate_setup records it in truth/optics.json."""
    sim = sim_config(wildcards)
    return {k: v for k, v in sim.items() if k != "render"}


def lenslet_sim_config(dataset):
    """The simulate slice the lenslet renders read: everything but the ideal renders'
    supersampling (``render.ideal_supersample``, rules ground_truth_render*), whose
    change re-renders the ideal views alone."""
    sim = ds_config(dataset)["simulate"]
    render = {k: v for k, v in sim["render"].items() if k != "ideal_supersample"}
    return {**sim, "render": render}


def view_geometry(wildcards):
    """The convert settings that fix the view geometry (never the image content)."""
    conv = stage_config("convert")
    return {
        "view_spacing_px": conv["view_spacing_px"],
        "even_size": conv["even_size"],
    }


def gt_render_views(dataset):
    """Ideal renders: every central view, and the complete set of the middle shot."""
    out = [(c, centre(dataset)) for c in cams(dataset)]
    out += [(full_set_cam(dataset), v) for v in views(dataset) if v != centre(dataset)]
    return out


def simulate_targets(dataset):
    if not is_synthetic(dataset):
        return []
    out = [data(dataset, "lenslet", f"{c}.png") for c in cams(dataset)]
    out.append(res(dataset, "ground_truth", "cameras.json"))
    for cam, view in gt_render_views(dataset):
        out.append(res(dataset, "ground_truth", "renders", cam, f"{view}.png"))
    return out


# --- helpers of rules/synthesis.smk ---------------------------------------------------


def synthesis_inputs(wildcards):
    d = wildcards.dataset
    out = {
        "calibration": res(d, "calibration", "cameras.json"),
        "rig": res(d, "reg_b", "rig.json"),
        "view_sets": view_sets(d, array_cams(d)),
    }
    if is_synthetic(d):
        out["truth"] = res(d, "ground_truth", "cameras.json")
    return out


def synthesis_exp_inputs(wildcards, exp):
    """Inputs of synthesis_exp<exp> - the views, cameras and the depth maps (and on
    synthetic data the true depth) of the views the experiment reads."""
    d = wildcards.dataset
    out = synthesis_inputs(wildcards)
    keys = experiment_views(d, exp)
    out["depth"] = [depth_view_path(d, k) for k in keys]
    if is_synthetic(d):
        out["true_depth"] = [true_depth_path(d, k) for k in keys]
        # the ground-truth cameras' runs with estimated depth, where asked for, on maps
        # made with them (an Exp. 3 part of the complete calibration reads none)
        if (
            stage_config("verify")["ground_truth_own_depth"]
            and getattr(wildcards, "cameras", "ground_truth") == "ground_truth"
        ):
            out["truth_depth"] = [depth_view_truth_path(d, k) for k in keys]
        if exp in (1, 2):
            # the targets' true depth, where rendered: their surface pixels (the dB lost
            # to calibration without the renderer's choices at occlusion edges)
            out["true_depth_targets"] = [
                true_depth_path(d, k) for k in experiment_gt_targets(d, exp)
            ]
    return out


def experiment_gt_targets(dataset, exp):
    """The targets of experiment ``exp`` (1 or 2) that have a true depth map."""
    from plenocal.verify.experiments import experiment_plan

    layout = synthesis_layout(dataset)
    plan = experiment_plan(
        layout, exp, layout.exp2_cams(stage_config("verify")["exp2_sets"])
    )
    have = {f"{c}/{v}" for c, v in gt_render_views(dataset)}
    return [t for _, targets in plan.values() for t in targets if t in have]


#: experiments whose camera sets run in jobs of their own (synthesis_exp<k>_part), which
#: synthesis_exp<k> joins - Exp. 3 renders every view of the array four times
SPLIT_EXPERIMENTS = (3,)


#: the verify settings that a synthesis job does not read, by experiment (and Exp. 3's
#: parts): a change to one of them leaves the job as it is. The parts render and keep each
#: target's errors per ring of pixels; the join scores them with the PSNR's border.
SYNTHESIS_UNREAD = {
    "1": ("exp2_sets", "exp3_view_stride"),
    "2": ("exp3_view_stride",),
    "3": ("exp2_sets",),
    "3_part": ("exp2_sets", "psnr_border_px"),
}


#: the verify settings of the real RVS only: a synthesis job that renders with the
#: project's DIBR (verify.renderer: dibr) reads none of them
RVS_ONLY_VERIFY_KEYS = ("rvs_binary", "rvs_blending_factor", "rvs_compare_dibr")


def synthesis_verify_config(unread):
    """The verify block but the keys in ``unread`` and, with the DIBR as the renderer,
    the RVS's own."""
    cfg = stage_config("verify")
    skip = set(unread) | (
        set(RVS_ONLY_VERIFY_KEYS) if cfg["renderer"] == "dibr" else set()
    )
    return {k: v for k, v in cfg.items() if k not in skip}


def synthesis_params(exp, part=False):
    """The params of scripts/synthesis.py for synthesis_exp<exp> (``part``: its _part
    jobs): the verify settings that the job reads (SYNTHESIS_UNREAD, RVS_ONLY_VERIFY_KEYS).
    """
    unread = SYNTHESIS_UNREAD[f"{exp}_part" if part else str(exp)]
    return {
        "experiment": exp,
        "verify": lambda wc: synthesis_verify_config(unread),
        "depth": lambda wc: synthesis_depth_config(),
        "views_dir": lambda wc: res(wc.dataset, "views"),
        "array_cams": lambda wc: array_cams(wc.dataset),
        "n_views": lambda wc: n_views(wc.dataset),
    }


def synthesis_camera_sets(dataset):
    """The calibration under test and, on synthetic data, the ground-truth cameras."""
    return ["complete"] + (["ground_truth"] if is_synthetic(dataset) else [])


def synthesis_parts(wildcards, exp):
    """The camera sets' runs of a split experiment (its _part jobs)."""
    d = wildcards.dataset
    base = res(d, "eval", f"synthesis_exp{exp}")
    return {
        "runs": [f"{base}/{c}.json" for c in synthesis_camera_sets(d)],
        "kept": [f"{base}/{c}.npz" for c in synthesis_camera_sets(d)],
    }


def synthesis_exp_join_inputs(wildcards, exp):
    """synthesis_exp<exp>: its inputs or, for a split experiment, its parts' runs with
    the cameras, the bounds and the depth maps whose quality the result reports (no
    view sets: the parts rendered them)."""
    out = synthesis_exp_inputs(wildcards, exp)
    if exp in SPLIT_EXPERIMENTS:
        del out["view_sets"]
        out.pop("truth_depth", None)
        out.update(synthesis_parts(wildcards, exp))
    return out


def synthesis_targets(dataset):
    return [res(dataset, "eval", f"synthesis_exp{e}.json") for e in (1, 2, 3)]
