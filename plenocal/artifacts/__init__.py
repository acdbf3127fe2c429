"""The files one stage writes and another reads, each with one typed definition: its
writing, its reading, a format name and version, and a clear error for a file of another
version (issue 16). Light modules (numpy and the standard library): any stage may import
them without pulling in OpenCV or COLMAP.

* :mod:`.reg_a` - ``reg_a/reg_a.json`` (registration A -> B, depth, merge, baseline, Table I)
* :mod:`.disparity` - ``views/<shot>/disparity.json`` (convert -> registration B)
* :mod:`.rig` - ``reg_b/rig.json`` (registration B -> depth, merge, Table I, synthesis)
* :mod:`.cameras` - ``cameras.json``, the plain camera file of every calibration and of
  the ground truth (merge, baseline_sfm, ground_truth -> depth maps, synthesis, Table I,
  gt_errors, the report)
* :mod:`.scale` - ``merge/scale.json`` (scale, Eq. 5 -> merge, Eq. 6, and gt_errors)
* :mod:`.tracks` - ``refine/tracks/<source>/`` (refine_tracks -> refine: one track set of
  the joint refinement, its points and their aligned observations)
* :mod:`.stage_warnings` - the ``warnings`` list of a stage's output (convert set-up,
  ``disparity.json``, ``features.json`` -> the report's first screen): one shape
* :mod:`.results` - the evaluation results that the report reads: ``eval/reprojection.json``
  (Table I), ``eval/gt_errors.json``, ``eval/synthesis_exp<k>.json`` (Figs. 6-10) and
  ``convert/quality.json``
"""
