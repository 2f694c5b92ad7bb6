"""The synthetic RGB-D generator (`v2c synth`): procedural and real CAD parts rendered with exact ground truth.

parts.py (part families, STEP import), scene.py (camera, lights, materials), occ.py (OCCT I/O and faces),
intersect.py (exact ray/primitive hits), render.py (ray casting, shading), noise.py (noise profiles),
dataset.py (scan folders).
"""
