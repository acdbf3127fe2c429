"""Synthetic inputs with known answers for the tests and the benchmarks (not part of the
package): lenslet images of textured planes (:mod:`.lenslets`), textured planes seen by
pinhole cameras with their true depth (:mod:`.planes`), and a small multi-plane scene
with camera arrays and N x N view sets for the SfM tests (:mod:`.scenes`), plane-sweep
cost planes with ties and gaps (:mod:`.costs`)."""
