"""Thresholds of VB-Rep extraction, each with its unit.

"scale units" are fractions of the part size estimate (FitResult.scale, metres), as in the paper, where models are
scaled to unit size: a threshold ``x`` in scale units is ``x * scale`` metres.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class VBRepConfig:
    """Every threshold and iteration count of VB-Rep extraction (`v2c.vbrep.extract.extract_vbrep`); the functions
    of v2c.vbrep take this object (or values read from it), never copies of its values as defaults."""

    # --- depth window of the ray casts (which crossings of a surface along a ray count)
    window_percentile: float = 0.5  # percent: the window spans the observed depths from this percentile ...
    window_near: float = 0.5  # ratio: ... times this (near end) to the (100 - window_percentile) percentile ...
    window_far: float = 1.5  # ratio: ... times this (far end)
    window_min_m: float = 0.01  # metres: the near end is at least this
    window_empty_m: tuple[float, float] = (0.05, 5.0)  # metres: the window of a scan without depth readings

    # --- vertices: intersection optimisation (paper: d_int, 5 px)
    d_int: float = 0.05  # scale units: an optimised vertex must lie within this of each of its surfaces and move
    #                      at most this far from its initial lift
    vertex_px: float = 5.0  # pixels: an optimised vertex must reproject within this of its image position
    vertex_iters: int = 12  # Gauss-Newton iterations of the vertex solves
    vertex_merge_gap_share: float = 0.25  # ratio: vertices of one kind optimised closer than this times the
    #                                       depth-gap threshold (max(int_gap * scale, int_gap_min_m)) merge

    # --- edge typing
    sample_step_px: float = 1.0  # pixels: spacing of the samples along each 2D edge
    side_probe_px: float = 2.0  # pixels: how far to each side of an edge the instance map is read
    int_band_px: float = 3.0  # pixels: two surfaces meeting within this of the 2D edge make it an intersection
    int_band_step_px: float = 0.5  # pixels: spacing of the rays across that band
    int_gap: float = 0.005  # scale units: ... or coming closer than this (in depth) within the band
    int_gap_min_m: float = 0.0007  # metres: floor of the depth-gap threshold (sensor noise)
    vis_px: float = 5.0  # pixels: a curved near face whose contour generator lies within this is a visibility edge
    vis_angle_deg: float = 30.0  # degrees: ... and the edge runs along that contour (image tangents this close)
    vis_step_px: float = 0.5  # pixels: step of the contour search
    vis_bisect: int = 5  # bisection steps refining a contour crossing found by that search (each halves the step)
    vis_face_px: int = 1  # pixels: a contour point must project within this of its face's own pixels
    smooth_uv_px: float = 5.0  # pixels: moving-average window over the edge samples' image positions before
    #                            lifting (removes the pixel staircase; the ends stay)
    smooth_samples: int = 5  # samples: mode filter window over the per-sample edge types
    min_run_px: float = 6.0  # pixels: type runs shorter than this are merged into their neighbours

    # --- projection onto the intersection curve
    curve_iters: int = 8  # Gauss-Newton iterations projecting samples onto both surfaces
    curve_slack_px: float = 1.0  # pixels: a sample projected onto the intersection curve may move in the image by
    #                              int_band_px plus this; one that moves farther keeps its start
    perpendicular_deg: float = 1.0  # degrees: plane normal and axis within this count as perpendicular (circle)
    parallel_deg: float = 1.0  # degrees: plane-plane normals within this have no line of intersection
    meet_tol: float = 0.01  # scale units: an intersection run is kept only where its two surfaces meet within
    #                         this (3D) of its lifted samples (at least ``meet_min_m``) ...
    meet_min_m: float = 0.001  # metres: floor of ``meet_tol``
    meet_share: float = 0.0  # ratio: ... for at least this share of its samples; otherwise, if its two lifts
    #                          also lie more than ``retype_gap`` apart (median, along the rays), it is retyped as
    #                          a silhouette of the nearer face (and an occluded edge of the farther one)
    retype_gap: float = 0.05  # scale units: see meet_share. Off by default (meet_share = 0): the ground-truth
    #                           rule calls surfaces within 0.3 mm an intersection even where the fitted ones miss;
    #                           meet_share 0.5 with retype_gap 0.05 gave 19 instead of 22 faces bounded by their
    #                           mesh outline on 23 scans but 91.7 % instead of 92.7 % edge-type accuracy, and
    #                           retype_gap 0 (any miss) 6 points less
    retype_conf: float = 0.5  # factor: confidence multiplier of such a retyped edge
    # --- tangent (G1) junctions: fillets, blends, a dome on a cylinder
    tangent_deg: float = 8.0  # degrees: an intersection run whose two surfaces' normals lie within this of each
    #                           other (median over its lifted samples) is a tangent junction: its samples go to
    #                           the surfaces' line of contact (`lift.contact_points`), not onto an intersection
    #                           solve that wanders where the surfaces barely cross, and it is marked tangent
    tangent_iters: int = 30  # alternating-projection steps of the contact points

    # --- topology (topology.py)
    snap_iters: int = 20  # Gauss-Newton iterations putting vertices and polylines onto their surfaces
    snap_tol: float = 1e-7  # metres: |signed distance| counted as on a surface
    snap_end_px: float = 0.0  # pixels: polyline samples this close to an end vertex's image point and behind it
    #                           (doubling back) are dropped; 0 = off. 3 px: 19 instead of 22 faces bounded by
    #                           their mesh outline on 23 scans, but edge-type accuracy 92.4 % instead of 92.6 %
    end_hook_deg: float = 45.0  # degrees: a polyline's first / last interior sample where the path from its end
    #                             vertex turns back (the angle at the sample, in the image, under this) is dropped,
    #                             repeatedly (`topology.drop_end_hooks`); 0 = off

    # --- post-processing (supplement)
    simplify_deg: float = 36.0  # degrees: two same-type edges of the same faces meeting at a vertex no other
    #                             edge uses (and that is not an outline corner) are merged into one when the
    #                             polyline turns there by less than this
    fold_deg: float = 30.0  # degrees: two such edges leaving their vertex within this angle of each other (one
    #                         boundary run past its turn and back along itself) become one edge ending where the
    #                         shorter one ends, when that end projects within fold_px of the longer one; 0 = off
    fold_px: float = 3.0  # pixels: ... (`postprocess._drop_fold_backs`)
    corner_scale_px: float = 5.0  # pixels: arm length of the turn measured along an edge to find its corners
    corner_deg: float = 20.0  # degrees: an edge whose image polyline turns by more than this at one point (a
    #                           corner of the outline) is split there
    corner_concentration: float = 0.7  # ratio: ... when that turn is at least this share of the turn over arms
    #                                    twice as long (arcs turn in proportion to the arm, corners do not)
    polyline_px: float = 0.1  # pixels: Ramer-Douglas-Peucker tolerance of non-analytic edge polylines in the image
    #                           (0.5 until 2026-11-27: a polyline inscribed in its curve by up to half a pixel cut
    #                           small round faces short; with meshes from the loops, corpus-val oracle faces
    #                           written within 2 % of their mesh 308 -> 323 of 544)
    min_edge_px: float = 5.0  # pixels: edges shorter than this in the image are dropped
    min_loop_edges: float = 4.0  # ratio: closed edges shorter than this times min_edge_px are dropped

    # --- ambiguity (which sheet of a surface the face is: boss or hole)
    sheet_max_pixels: int = 4000  # pixels: at most this many (seeded sample) per face to score the sheets
    sheet_ring_px: int = 3  # pixels: a face none of whose pixels has a reading takes the sheet that best meets the
    #                         readings of the other pixels within this of its outline (a hole's wall the sensor
    #                         did not read lies deeper than its rim, not on the near side of its cylinder)

    # --- faces the geometry stage left without a primitive
    fallback_min_px: int = 10  # pixels: such an instance this large gets a least-squares plane through its depth
    #                            points and its boundaries lifted onto its fitted neighbours (else: background)
    island_max_px: int = 25  # pixels: a connected piece of a faced instance, not its largest, smaller than this
    #                           goes to the faced instance around it (within speck_reach_px; `faces.absorb_islands`;
    #                           0: off) ...
    island_max_share: float = 0.05  # ... and than this share of the instance's pixels (a piece of a small face,
    #                                 split by noise, stays its own) ...
    island_keep_score: float = 1.0  # ... and never of an instance scored at least this (the oracle's ground truth,
    #                                 score 1: a true face seen in pieces; corpus-val oracle recall -0.3 points
    #                                 and edge-type -0.6 points when its pieces moved)
    speck_reach_px: float = 3.0  # pixels: a smaller instance without a face (a speck) is merged into the faced
    #                              instances nearest its pixels, within this (a speck of up to 9 px lies within
    #                              2 px of its outline), and the edge graph rebuilt (`faces.absorb_specks`)
    graph_simplify_px: float = 1.0  # pixels: Douglas-Peucker tolerance of that rebuilt graph (the fit's own,
    #                                 FitConfig.simplify_px)
    fallback_rms: float = 0.01  # scale units: ... if the plane fits that evidence this well
    fallback_flatness: float = 0.05  # ratio of singular values: ... and the evidence is not all on one line
    fallback_min_angle_deg: float = 5.0  # degrees: ... and the plane does not coincide with a fitted plane (within
    #                                      this angle and fallback_rms; evidence from at least two sources: its own
    #                                      depth, or a neighbour's edge each)
    fallback_min_view_deg: float = 5.0  # degrees: ... and its evidence's centroid sees it at least this far from
    #                                     edge-on (a free plane there is no surface its pixels show; the upright
    #                                     sugar box's side, 0.5 degrees behind edge-on, came out as 10 STEP slivers)
    fallback_own_first: bool = True  # a plane-labelled face's free fallback plane is fitted to its own depth
    #                                  points where they form a patch (flatness), and a neighbour's lifted edge
    #                                  joins them only within fallback_rms of that plane (`faces.own_first_plane`);
    #                                  other labels and False: every source together (before 2026-11-29; a curved
    #                                  face's own few points passed as a plane its edges had refused)
    fallback_trim: float = 0.8  # share: the free plane and sphere fits are refitted on this share of the evidence
    #                             closest to their first fit
    fallback_fit_iters: int = 10  # Gauss-Newton iterations of the cylinder fit with a given axis
    fallback_curved: bool = True  # an unfitted instance with a curved label gets that type on an axis its fitted
    #                               neighbours suggest, within fallback_rms (`faces.curved_fallback`), in place of
    #                               its free plane (corpus training split, oracle: all 43 type errors were free
    #                               planes on fillets, rounded rims, chamfers and ball ends of 10-70 pixels)
    fallback_axis_cross_deg: float = 10.0  # degrees: two neighbouring planes this far apart or more suggest the
    #                                        axis along their line of intersection (a blend between them)
    fallback_strip_axis: bool = True  # a cylinder's candidate axes include its evidence's long direction (the
    #                                   principal axis of its points: a fillet or rounded edge is a strip along its
    #                                   axis, and its neighbours may suggest no direction along it) ...
    fallback_strip_elongation: float = 2.0  # ratio: ... when the evidence is at least this many times longer than
    #                                         wide (RMS extents along its first two principal axes): a patch as wide
    #                                         as long has no long direction (corpus training split, oracle: from 2.0
    #                                         no such candidate made a fallback cylinder's axis worse; in-family seed
    #                                         9000 scan 37, a knob's 34-point patch 1.6 times longer than wide, took
    #                                         one 56 degrees off)
    fallback_curved_sigma: float = 2.0  # ratio: ... and its RMS within this many depth-noise sigmas
    #                                     (sigma_depth_coeff_per_m z^2 at the evidence's median depth). Chosen on
    #                                     the validation sets: without it a knob flute of seed 9000 took a wrong
    #                                     axis (oracle alignment 0.0049 -> 0.0120); corpus-val gains are the same

    # --- meshes
    mesh_stride_px: int = 1  # pixels: spacing of the back-projected pixel grid of each face mesh
    mesh_max_edge: float = 0.2  # scale units: triangles with a longer side (jumps between crossings) are dropped
    mesh_chord_angle_rad: float = 0.25  # radians: a curved face's (not a torus's) mesh edge lying off the surface
    #                                     like a chord subtending more than this at the
    #                                     surface's smaller curvature radius is split onto the surface
    #                                     (`mesh.refine_curved`; flat facets then lose at most this^2 / 24 = 0.26 %
    #                                     of the surface's area; a 1.7 mm hole wall meshed on the pixel grid lost
    #                                     6 %, and its STEP face read back 6 % larger than the VB-Rep; 0: off)
    mesh_refine_levels: int = 4  # ... at most this many times (each halves the split edges)
    mesh_refine_max_triangles: int = 400_000  # ... while the face's mesh stays under this many triangles
    mesh_island_max_share: float = 0.01  # fraction: a piece of a face's mesh (not its largest) with at most this
    #                                      share of the mesh's area ...
    mesh_island_max_dist: float = 0.05  # scale units: ... whose vertices lie farther than this (median) from every
    #                                     measured point of the part is dropped (`mesh.drop_stray_islands`: rays
    #                                     that pass a curved face's near sheet meet its far one; 0.05 part sizes is
    #                                     issue 16's bound on a face's distance from the measured part)
    mesh_bound_pad: float = 0.05  # scale units: triangles with a corner outside the part's box (its observed points'
    #                               0.5-99.5 percentiles per axis) padded by this are dropped (a wrong surface seen
    #                               nearly edge-on runs off past the part; a cylinder or cone may reach one part
    #                               size past the part's nearest point in depth: a hole's wall; negative: no box)
    mesh_bound_percentile: float = 0.5  # percent: the part's box spans its observed points from this percentile
    #                                     to (100 - this) per axis
    mesh_bound_pad_unmeasured: float = 0.1  # scale units: ... padded by this for a face with no depth reading on
    #                                          more than mesh_unmeasured_share of its pixels (placed by its edges)
    mesh_unmeasured_share: float = 0.7  # fraction
    mesh_loose_min_conf: float = 0.6  # ... and a face confidence at least this (a wrong face seen edge-on is unsure)
    mesh_plane_long: bool = True  # a plane's triangle longer than mesh_max_edge is kept inside that box when the
    #                               face's confidence is at least mesh_loose_min_conf (a plane seen nearly edge-on
    #                               spans much depth per pixel, and it has one crossing)
    mesh_from_loops: bool = True  # a face whose loops bound a valid image region is meshed from them (the trimmed
    #                               face, `v2c.vbrep.loop_mesh`), else from its pixel region
    loop_ring_pieces: int = 8  # count: a curved face's loop polylines are followed on its surface, each segment
    #                            cut into this many pieces moved onto it, before the loop's image region is taken
    #                            (`loop_mesh._on_surface_between`; 1: straight image segments)
    loop_mesh_min_iou: float = 0.8  # ratio: ... when that region's intersection over union with the face's pixels
    #                                 is at least this. Chosen on the corpus validation VB-Reps (oracle, 30 scans):
    #                                 face precision 0.968 before, 0.892 with every valid loop region, 0.933 with
    #                                 0.6, 0.959 with 0.8 (loops of small faces run pixels off their region)
    loop_mesh_max_take: float = 0.25  # ratio: ... and covers less than this share of any other face's pixels (a
    #                                   loop a pixel off its outline swallowed a 16 px neighbour, hidden behind the
    #                                   mesh: corpus-val oracle VB-Reps, mean face precision 94.9 % without this
    #                                   condition, 96.9 % with it, as with pixel meshes; within-2 % faces 329 -> 327)
    mesh_surface_tol: float = 0.05  # scale units: a mesh ray's closest approach to a sheet it misses is moved onto
    #                                 the surface when within this of it, else dropped (as are vertices outside the
    #                                 depth window, e.g. at the camera centre); d_int's value
    mesh_evidence_tol: float = 0.05  # scale units: a face's mesh keeps to what its own pixels measured: triangles
    #                                  with a vertex on (or next to) a pixel with a reading that lies farther than
    #                                  this from all of them are dropped, then pieces with no such vertex within it
    #                                  (`v2c.vbrep.mesh.clip_to_measured`; a face seen nearly edge-on); 0 = never.
    #                                  Faces with no reading on more than mesh_unmeasured_share of their pixels
    #                                  (placed by their edges) are not clipped; a face's loop mesh is not used when
    #                                  its judged vertices lie farther at their median (`mesh.beyond_measured`).
    #                                  Issue 16's bound for far faces (0.05 part sizes), not tuned
    mesh_evidence_graze_deg: float = 80.0  # degrees: ... only vertices whose ray meets the surface at least this
    #                                        far from its normal are clipped (a crossing nearer face-on moves by at
    #                                        most 1/cos(80) = 5.8 times the fit's error along the ray; the failures
    #                                        were at 87-89 degrees); real frames, whose boards bow and whose labels
    #                                        stand off them, lost triangles at 70-73 degrees to 0.05 part sizes
    #                                        and their outlines broke into pieces (a cracker box's top in 3 STEP
    #                                        faces)
    mesh_evidence_median: bool = True  # a face whose pixel mesh lies farther than mesh_evidence_tol from its own
    #                                    readings at the median of its vertices on pixels with a reading, at any
    #                                    angle, gets none (`mesh.beyond_measured`: its surface misses what its
    #                                    pixels measured, a wrong primitive: a 19 px face fitted as a 101 mm
    #                                    cylinder 8 mm off its readings)
    unseen_surface_plane: bool = True  # a curved face left without a mesh because its surface misses its own
    #                                    readings gets the plane through them instead, where that plane meets them
    #                                    within mesh_evidence_tol, and the edges and meshes are extracted again
    #                                    (`faces.planes_for_unseen_surfaces`): the face stays where the sensor saw it
    mesh_evidence_min_share: float = 0.5  # fraction: ... and a face whose clipped mesh keeps less than this share
    #                                       of its area gets none (its readings contradict the surface over most
    #                                       of it: a wrong primitive). Half, not tuned

    # --- confidence (docs/vbrep.md)
    conf_residual: float = 0.02  # scale units: fit residual at which the residual factor is exp(-1)
    conf_length_px: float = 15.0  # pixels: edge length at which the length factor is 1 - exp(-1)
    conf_angle_deg: float = 20.0  # degrees: surface angle at which the angle factor saturates to 1
    conf_depth: float = 0.03  # scale units: edge-to-depth disagreement at which the depth factor is exp(-1)
    conf_calibration: str | None = "shipped"  # the map from raw confidence to probability right
    #   (v2c.vbrep.calibration): "shipped" = v2c/vbrep/confidence_calibration.json, a path, or None (raw)
    sigma_depth_coeff_per_m: float = 0.0015  # 1/m: depth noise sigma = coeff * z^2, a floor under the fit residual
    #   in the positional uncertainty (v2c.vbrep.uncertainty)
    sigma_depth_correlated: float = 1.0  # fraction of that depth sigma common to a whole face (not averaged out)
    sigma_min_angle_deg: float = 5.0  # degrees: intersection angle floor of an edge's positional sigma

    seed: int = 0  # seeds the per-face pixel samples of the sheet choice
