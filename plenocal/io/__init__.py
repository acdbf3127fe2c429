"""Files on disk that no single stage owns.

* :mod:`.files` - atomic writes, JSON, ``.npy`` and images (8/16-bit PNG).
* :mod:`.raytrix` - the Raytrix calibration XML (micro-lens grid, lens types).
"""
