"""Test scenes: example inputs with known geometry for the tests (not shipped in the packages).

- `scenes.vbrep`: hand-built analytic VB-Reps (a box from a corner, an upright cylinder) and the camera helpers.
- `scenes.raycast`: analytic scenes ray-cast in numpy, turned into the stage inputs of VB-Rep extraction.
- `scenes.revolved`: a hand-built VB-Rep with every analytic surface type, for the STEP export.
- `scenes.truth`: ground-truth VB-Reps of a true part's B-rep (build123d / OCCT), small generated scans.

Importable as ``scenes`` from every test: pytest puts tests/ on sys.path (rootdir-relative, no tests/__init__.py).
"""
