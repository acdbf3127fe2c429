"""The verification of the paper (Section III): Table I and view synthesis.

* :mod:`.reprojection` - Table I: reprojection error of the calibrated views.
* :mod:`.sfm_baselines` - Table I's naive baselines: A + SfM of the other views, and SfM
  of all views from scratch.
* :mod:`.gt_errors` - the calibration against the simulator's ground truth.
* :mod:`.synthesis` - the view-synthesis experiments 1-3 (PSNR of a left-out view).
* :mod:`.dibr` - depth-image-based rendering, the renderer of the experiments.
* :mod:`.rvs` - MPEG's Reference View Synthesizer, the paper's renderer, where installed.
"""
