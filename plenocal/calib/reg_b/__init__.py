"""Registration B (Section II-C of the paper, Eqs. 1-4): the N x N subaperture set of one
plenoptic camera, ``rig.json``.

* :mod:`.datasheet` - ``camera.yaml``: its schema and its reading.
* :mod:`.rig` - the view cameras of either model and the ``rig.json`` document.
"""
