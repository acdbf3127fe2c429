"""The simulator: a physically based plenoptic 2.0 camera array with ground truth.

* :mod:`.dataset` - a synthetic dataset: set-up, datasheet, calib.xml and every shot.
* :mod:`.optics_setup`, :mod:`.mla`, :mod:`.scene`, :mod:`.raytrace`, :mod:`.sensor` -
  the camera, the multi-focus MLA, the scene, the ray tracer, the sensor.
* :mod:`.groundtruth` - the pinhole camera of every view from the traced chief rays,
  ideal renders and depth.
"""
