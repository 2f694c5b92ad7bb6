"""Instance extraction from label + boundary maps (v2c.segment.instances) on synthetic maps with known answers."""

from __future__ import annotations

import numpy as np

from v2c.segment.data import boundary_map
from v2c.segment.instances import InstanceConfig, extract_instances


def _faces_and_labels() -> tuple[np.ndarray, np.ndarray, dict[int, int]]:
    """A 60 x 80 map: background frame, face 1 (label 1) left, face 2 (label 7) right, face 3 (label 3) bottom,
    face 4 (label 1, same as face 1) a square inside face 2's column range but separated by boundaries."""
    faces = np.zeros((60, 80), np.uint16)
    faces[5:35, 5:40] = 1
    faces[5:35, 40:75] = 2
    faces[35:55, 5:75] = 3
    faces[12:24, 50:62] = 4
    lab_of = {0: 0, 1: 1, 2: 7, 3: 3, 4: 1}
    labels = np.vectorize(lab_of.get)(faces).astype(np.uint8)
    return faces, labels, lab_of


def _match(seg_inst: np.ndarray, faces: np.ndarray) -> dict[int, int]:
    """Map each gt face to the instance covering it, asserting a one-to-one exact match."""
    out = {}
    for f in np.unique(faces[faces > 0]):
        ids = np.unique(seg_inst[faces == f])
        assert len(ids) == 1, f"face {f} split into instances {ids}"
        out[int(f)] = int(ids[0])
    assert len(set(out.values())) == len(out), "two faces share an instance"
    assert np.array_equal(seg_inst > 0, faces > 0)
    return out


def test_exact_masks_from_labels_and_boundaries() -> None:
    faces, labels, lab_of = _faces_and_labels()
    seg = extract_instances(labels, boundary_map(faces))
    m = _match(seg.instances, faces)
    assert seg.num_instances == 4
    for f, i in m.items():
        assert seg.labels[i] == lab_of[f]
        assert seg.scores[i] == 1.0
    assert seg.labels[0] == 0 and seg.method == "learned"


def test_label_noise_without_boundary_is_merged() -> None:
    faces, labels, _ = _faces_and_labels()
    noisy = labels.copy()
    noisy[8:20, 8:20] = 4  # a 144-px patch of the wrong label inside face 1, no boundary around it
    seg = extract_instances(noisy, boundary_map(faces))
    m = _match(seg.instances, faces)
    i1 = m[1]
    assert seg.labels[i1] == 1  # majority label of the merged instance
    area1 = int((faces == 1).sum())
    assert abs(seg.scores[i1] - (area1 - 144) / area1) < 1e-6


def test_small_specks_are_absorbed_and_probabilities_label() -> None:
    faces, labels, _ = _faces_and_labels()
    bnd = boundary_map(faces)
    noisy = labels.copy()
    noisy[40:43, 20:23] = 9  # a 9-px speck enclosed by a predicted boundary ring
    bnd2 = bnd.copy()
    bnd2[39:44, 19:24] = True
    bnd2[40:43, 20:23] = False
    probs = np.zeros((18,) + faces.shape, np.float32)
    probs[noisy.astype(np.int64), np.arange(60)[:, None], np.arange(80)[None, :]] = 0.8
    probs[0] += 0.2 * (noisy != 0)
    seg = extract_instances(noisy, bnd2, probs=probs, cfg=InstanceConfig(min_area_px=24))
    m = _match(seg.instances, faces)
    assert seg.labels[m[3]] == 3
    # background probability is excluded and the rest renormalised: 0.8 of the face pixels -> score ~1 minus speck
    area3 = int((faces == 3).sum())
    assert abs(seg.scores[m[3]] - (area3 - 9) / area3) < 1e-5


def test_region_restricts_instances() -> None:
    faces, labels, _ = _faces_and_labels()
    region = np.zeros(faces.shape, bool)
    region[:, :40] = True
    seg = extract_instances(labels, boundary_map(faces), region=region)
    assert not (seg.instances[:, 40:] > 0).any()
    left = faces.copy()
    left[:, 40:] = 0
    assert np.array_equal(seg.instances > 0, left > 0)
    assert seg.num_instances == 2


def test_soft_boundary_cuts_on_the_ridge() -> None:
    """A 7-px strip between two faces (all one label) under soft predicted boundary bands that are wider on the
    outer faces' side than on the strip's: the nearest-core fill cuts half-way between the cores (inside the outer
    faces), flooding in order of boundary probability cuts on the ridges (the true boundaries)."""
    faces = np.zeros((40, 60), np.uint16)
    faces[2:38, 2:58] = 1
    faces[18:25, 2:58] = 2  # the strip, rows 18-24
    faces[25:38, 2:58] = 3
    labels = np.where(faces > 0, 1, 0).astype(np.uint8)
    rows = np.arange(40, dtype=np.float32)[:, None] + 0.5
    d = np.minimum(np.abs(rows - 18.0), np.abs(rows - 25.0))  # distance to the nearer boundary (pixels)
    sigma = np.where((rows > 18.0) & (rows < 25.0), 1.5, 4.0)  # band narrower inside the strip
    prob = np.exp(-0.5 * ((d - 0.5) / sigma) ** 2)  # 1.0 on both ridge pixels of each boundary
    prob = np.broadcast_to(prob, faces.shape).astype(np.float32)
    seg = extract_instances(labels, prob)
    m = _match(seg.instances, faces)
    for f, i in m.items():
        assert np.array_equal(seg.instances == i, faces == f)
    nearest = extract_instances(labels, prob, cfg=InstanceConfig(flood_levels=()))
    assert not np.array_equal(nearest.instances == nearest.instances[21, 30], faces == 2)


def _probs_of(labels: np.ndarray, p_own: float) -> np.ndarray:
    """(18, H, W) class probabilities: ``p_own`` on each pixel's label, the rest spread evenly over the others."""
    probs = np.full((18,) + labels.shape, (1.0 - p_own) / 17, np.float32)
    probs[labels.astype(np.int64), np.arange(labels.shape[0])[:, None], np.arange(labels.shape[1])[None, :]] = p_own
    return probs


def _three_faces(
    height: int, strip: tuple[int, int], strip_label: int, band: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(faces, labels, boundary probability) of a (height, 60) map: face 1 (label 1) above, a strip (face 2, rows
    strip[0]:strip[1], label strip_label) and face 3 (label 3) below, all under one predicted boundary band (rows
    band[0]:band[1], probability 0.9)."""
    faces = np.zeros((height, 60), np.uint16)
    faces[2 : strip[0], 2:58] = 1
    faces[strip[0] : strip[1], 2:58] = 2
    faces[strip[1] : height - 2, 2:58] = 3
    labels = np.vectorize({0: 0, 1: 1, 2: strip_label, 3: 3}.get)(faces).astype(np.uint8)
    prob = np.zeros(faces.shape, np.float32)
    prob[band[0] : band[1]] = 0.9
    return faces, labels, prob


def _thin_wall() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A 4-px strip (label 7, cylinder Z) between two planes (labels 1 and 3), all three under one predicted
    boundary band 8 px wide: the strip has no pixel of low boundary probability (a hole's wall under its rim)."""
    return _three_faces(40, (18, 22), 7, (16, 24))


def test_face_inside_the_boundary_band_gets_its_own_instance() -> None:
    faces, labels, prob = _thin_wall()
    probs = _probs_of(labels, 0.9)
    seg = extract_instances(labels, prob, probs=probs)
    m = _match(seg.instances, faces)
    assert np.array_equal(seg.instances == m[2], faces == 2)
    assert seg.labels[m[2]] == 7
    # without band markers the strip is flooded by its neighbours
    off = extract_instances(labels, prob, probs=probs, cfg=InstanceConfig(band_marker_px=0))
    assert not np.isin(faces[off.instances == off.instances[20, 30]], [2]).all()
    # an unsure strip (mean probability of its label under band_marker_prob) is label noise: no marker
    unsure = probs.copy()
    unsure[:, faces == 2] = _probs_of(labels, 0.5)[:, faces == 2]
    noisy = extract_instances(labels, prob, probs=unsure)
    assert noisy.num_instances == 2


def test_band_next_to_its_own_face_is_not_a_marker() -> None:
    """The band halves of two faces carry their faces' labels and touch their markers: no extra instance."""
    faces, labels, prob = _thin_wall()
    labels[faces == 2] = 1  # the strip is painted with its upper neighbour's label: the band is that face's edge
    seg = extract_instances(labels, prob, probs=_probs_of(labels, 0.9))
    assert seg.num_instances == 2
    assert (seg.instances[faces == 1] == seg.instances[5, 30]).all()


def test_open_contact_keeps_confident_faces_of_two_types_apart() -> None:
    """A confident cylinder patch inside a plane with no predicted boundary stays an instance (a hole wall the
    boundary head missed); an unsure one is label noise and merges, as does a patch of another plane class."""
    faces, _, _ = _faces_and_labels()
    region = faces == 1
    patch = np.zeros(faces.shape, bool)
    patch[8:20, 8:20] = True
    no_boundary = np.zeros(faces.shape, bool)
    for lab, p_own, apart in ((7, 0.95, True), (7, 0.6, False), (4, 0.95, False)):
        noisy = np.where(region, 1, 0).astype(np.uint8)
        noisy[patch] = lab
        seg = extract_instances(noisy, no_boundary, probs=_probs_of(noisy, p_own))
        assert (seg.num_instances == 2) == apart, (lab, p_own)
        if apart:
            assert np.array_equal(seg.instances == seg.instances[10, 10], patch)
            assert seg.labels[seg.instances[10, 10]] == 7


def _edge_on_face() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A 12-px strip (face 2) seen nearly edge-on between two faces, painted with its upper neighbour's label (two
    planes of one axis class), the predicted boundary band covering it whole; the strip returns no depth."""
    faces, labels, prob = _three_faces(60, (20, 32), 1, (17, 35))
    return faces, labels, prob, faces == 2


def test_edge_on_face_without_depth_gets_its_own_instance() -> None:
    faces, labels, prob, unmeasured = _edge_on_face()
    probs = _probs_of(labels, 0.9)
    seg = extract_instances(labels, prob, probs=probs, unmeasured=unmeasured)
    strip = seg.instances == seg.instances[26, 30]
    iou = (strip & (faces == 2)).sum() / (strip | (faces == 2)).sum()
    assert iou > 0.85, iou
    assert seg.num_instances == 3
    assert seg.labels[seg.instances[26, 30]] == 1
    # the same band where the strip is measured (a boundary between measured faces), or with no depth map: the
    # band beside face 1 is that face's edge, and the flooding splits the strip between its neighbours
    for um in (np.zeros_like(unmeasured), None):
        plain = extract_instances(labels, prob, probs=probs, unmeasured=um)
        assert plain.num_instances == 2
        for i in np.unique(plain.instances[faces == 2]):
            got = plain.instances == i
            assert (got & (faces == 2)).sum() / (got | (faces == 2)).sum() < 0.5
    # a band of one label too thin for a core (under 2 x band_core_px + 1 = 7 px: here rows 17-22) is not a marker
    thin, lab_thin, prob_thin = _three_faces(60, (20, 23), 1, (17, 26))
    seg_thin = extract_instances(lab_thin, prob_thin, probs=_probs_of(lab_thin, 0.9), unmeasured=thin == 2)
    assert seg_thin.num_instances == 2
