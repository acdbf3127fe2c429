"""plenocal: calibration of plenoptic 2.0 camera arrays, the paper's stages as folders.

The workflow (``Snakefile``, ``rules/``) calls one script per rule (``scripts/``); the
logic lives here, one folder per stage of the paper and one for its verification:

* :mod:`plenocal.simulate` - the synthetic capture (simulator) and its ground truth
  (:mod:`.simulate.groundtruth`: the traced pinhole camera of every view).
* :mod:`plenocal.convert` - lenslet image -> N x N subaperture views (RLC, Fig. 1a).
* :mod:`plenocal.calib` - the calibration (Section II):

  * :mod:`.calib.reg_a` - registration A, SfM of the central views (Section II-B);
  * :mod:`.calib.reg_b` - registration B, the subaperture set from the datasheet
    (Section II-C, Eqs. 1-4): :mod:`.datasheet`, :mod:`.paper_model`,
    :mod:`.exact_model`, :mod:`.rig`;
  * :mod:`.calib.scale` - Eq. 5; :mod:`.calib.merge` - Eq. 6.

* :mod:`plenocal.depth` - depth maps of subaperture views (Fig. 4c; used by Eq. 5 and
  the view synthesis).
* :mod:`plenocal.verify` - Table I (:mod:`.reprojection`, :mod:`.sfm_baselines`), the
  view-synthesis experiments (:mod:`.synthesis`, :mod:`.dibr`, :mod:`.rvs`) and the
  errors against the ground truth (:mod:`.gt_errors`, :mod:`.rig_truth`).
* :mod:`plenocal.export` - the calibration as plain JSON, MPEG-I JSON, COLMAP model.
* :mod:`plenocal.report` - the HTML report.
* :mod:`plenocal.artifacts` - the files one stage writes and another reads, each typed
  and versioned.
* :mod:`plenocal.io` - file writing and reading shared by all (:mod:`.io.files`) and
  the Raytrix calibration XML (:mod:`.io.raytrix`).

Shared at the top: :mod:`.camera` (pinhole cameras, poses), :mod:`.optics` (thin-lens
plenoptic optics), :mod:`.grid` (the microlens grid), :mod:`.viewgeom` (which sensor
point a view pixel samples), :mod:`.names` (shot and view names), :mod:`.config` (the
config schema), :mod:`.rulelog` (a rule's logging) and :mod:`.cli` (``plenocal
convert``).
"""
