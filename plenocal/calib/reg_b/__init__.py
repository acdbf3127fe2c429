"""Registration B (Section II-C of the paper, Eqs. 1-4): the N x N subaperture set of one
plenoptic camera, ``rig.json``.

* :mod:`.datasheet` - ``camera.yaml``: its schema, its checks and its typed reading.
* :mod:`.paper_model` - the paper's model: every symbol of Section II-C (Eqs. 1-3) and
  the inverse check of Eqs. 2-3.
* :mod:`.exact_model` - the view geometry that the thin-lens optics give (no rotation,
  shifted principal points).
* :mod:`.rig` - the view cameras of either model (Eq. 4) and the ``rig.json`` document.

The comparison with the simulator's ground truth is :mod:`plenocal.verify.rig_truth`.
"""
