"""Training of the corner detector (torch) and its export to ONNX: ``alcn pose train-corners``.

The network (:class:`pose.corner_net.CornerNet`) is trained densely: each step takes crops of
``crop_cells x crop_cells`` output cells from the labelled frames of
:func:`pose.corner_data.build_frames` (most of them around a visible part), each jittered after
the normalizer where asked (:func:`jitter_crops`: contrast, gain ramp, offset, noise), and minimises the
cross-entropy of the cells' labels (part cells weighted by ``corner_weight``, the cells
between ``pos_radius`` and ``neg_radius`` of a part ignored) plus the smooth L1 loss of the
offsets. Every background cell of a crop is a negative, the hard ones near the box included, so
no hard-negative mining is needed.

The training's length (:data:`ITERATIONS`, :data:`BATCH_SIZE`): 4000 steps of 64 crops, 8 times
the crops of the 2000 steps of 16 before, took the final training loss from 0.43-0.47 to
0.22-0.24 and every row of Table 1 up (sums over #1-#8 of ``alcn data pose --frames 30``, the
two-loop training sequence, mean of 3 seeds; before / after): none 721.1 / 771.1, DoG 690.0 /
765.6, Tan-Triggs 655.6 / 733.3, ALCN 695.6 / 752.2, lite ALCN 694.4 / 756.7; the held-out
scene's #1: none 76.7 / 93.3, DoG 94.4, Tan-Triggs 88.9, ALCN 76.7 / 74.4 (80.7 over 5 seeds),
lite ALCN 73.3 / 93.3% (``runs/big``; networks trained on an H100 by this module's loop with
``device="cuda"``, 16 at a time, 1.5-2.2 min each; on the 2-core CPU a network takes about 8
min). Tried with it on the same GPU, not kept (3 seeds, the old length): the mean of the
weights over the steps (an exponential moving average, 0.998) and a network distilled from
the 3 seeds' mean probabilities; neither raised the held-out scene's #1 above the seeds'
spread (none 68.9 and 73.3, ALCN 66.7 and 72.2, against 65.6 and 83.3 on that run). The mean
of the 3 seeds' networks at test time (three networks a frame) posed 93.3 and 86.7% of it
(``runs/ensemble``), the first hint that the single networks were too noisy, not too small.

The novel views' distance (:data:`pose.corner_data.NOVEL_DISTANCE`, 0.7-1.2 of their view's;
0.85-1.2 before): what the held-out scene's #1 lost was among its frames 1-6 (from 0), which are
nearer (431-481 mm) than every training view in their directions (600-612 mm there, 455 mm the
nearest of all) and 16.6-19.4 deg from them; #3, #5 and #8 of the first scene come within 425-459 mm
of a box whose nearest training view is at 491 mm. With novel views down to 0.7 of their view's
distance the network sees the box as large as there. One torch thread per network on the 2-core CPU,
4000 steps of 64 crops, no normalization, the held-out #1 for seeds 0 / 1 / 2 (``runs/s14``): 96.7 /
96.7 / 100% against 83.3 / 93.3 / 96.7 with 0.85-1.2, every close frame posed (before: frames 1, 2,
4, 5 and 6 of seed 0 posed 8-22 px off, frames 1 and 2 of seed 1); seed 0 on the first scene's
#1-#8: 790.0 against 773.3 lit (#5 93.3, #8 96.7) and 796.7 either way under the training light.
With the gain ALCN in front the held-out #1 went from 66.7 / 90.0 / 96.7 to 96.7 / 86.7 / 96.7%
(mean 84.4 -> 93.3): seed 0 no longer lost its first 10 frames. The first scene's Table 1 retrained
with it (3 seeds, ``runs/s14/lit``, README): none 774.4 lit over #1-#8, the gain ALCN 743.3 with
75.6% on #5, against 767.8 and 755.6 (80.0 on #5) for the H100's networks with 0.85-1.2 (another
network at each seed): differences within the spread of single networks (723.3-790.0).

The jitter after the normalizer (:func:`jitter_crops`, ``jitter=True``; off by default): the copies'
intensity change ``a I + b`` is what makes the network without normalization robust (below), but
behind a normalizer the copies of a view normalize to nearly one input, and the network behind
ALCN saw less variety than the one without: it lost more of #5-#8 to the light (25.6 points
against 14.4). With ``jitter`` each crop gets a contrast (log-uniform in 1/1.5-1.5), a gain ramp
across it (``exp(gx u + gy v)``, ``gx, gy`` in +-0.4), an offset (+-0.3) and noise (sigma up to
0.15) on the standardized input the network sees, drawn from a stream of its own so that the crops
drawn are those of the seed without it. Table 1's first scene, the same 3 seeds and novel views
0.7-1.2, every row jittered, without / with it (one torch thread per network, ``runs/s15``; sums
over #1-#8 lit, #5, #5-#8, the sum under the training light): gain ALCN 743.3 / 767.8 (every seed
higher: 723.3 / 770.0, 756.7 / 776.7, 750.0 / 756.7), #5 75.6 / 86.7, #5-#8 360.0 / 381.1,
training light 772.2 / 782.2; none 774.4 / 771.1 (790.0 / 756.7, 763.3 / 776.7, 770.0 / 780.0),
#5 80.0 / 81.1, #5-#8 377.8 / 377.8, training light 785.6 / 793.3, the held-out scene's #1 97.8 /
93.3% (each seed 93.3: two frames 6-14 px off); the DoG 768.9 / 758.9, #5 85.6 / 81.1;
Tan-Triggs 758.9 / 752.2, #5 78.9 / 75.6. What the
light takes from #5-#8 fell from 25.6 to 12.2 points behind ALCN and rose from 14.4 to 17.8
without normalization. It helps ALCN alone, and it is off by default so that none keeps the
held-out scene's 95% and every table stays as measured; ALCN's best recipe is with it.

The parts and the scale (the defaults, ``divisions=2``, ``scale=0.75``): the network finds the
26 points of the box's surface lattice (:func:`pose.box.box_parts`: corners, edge middles,
face centres) in frames downscaled to 0.75, where the design measured below found the 8 corners at
0.5. On #1 of ``alcn data pose --frames 30`` (no normalization, seed 0) the 26 parts at 0.5 were
found among the candidates at 76% of the visible ones (face centres 80-100%, corners 37-100%: a
corner's window is three quarters table) and posed 86.7%, the lost frames 5.0-5.6 px off. On the
held-out scene (``alcn data pose --seed 1``: another box texture, table and trajectory, its own
training sequence; #1), where the 8 corners posed 20, 0 and 0% (3 seeds): 26 parts at 0.5 33.3%
(ALCN in front 36.7), at 0.75 56.7% (ALCN 53.3), at 1.0 50.0%; a wider zoom of the homographies
(0.75-1.6 instead of 0.8-1.25) 20.0%. The first frames of that scene are the closest views (431-510
mm, where 3 of the 30 training views are nearer than 490 mm), and there the background class
outscores 12 of the 19 visible parts. Table 1 with the defaults (3 seeds, ``runs/table1_v6``): #1
98.9 +- 1.6% without normalization (96.7, 100, 100) and with ALCN (100, 100, 96.7), 97.8 with the DoG,
87.8 with Tan-Triggs; the README has every sequence and the held-out scene.

Most poses lost on the other sequences were wrong, not missing: a pose from 5 chance inliers
among the 130 candidates of a whole frame, kept, then the prior that gated the next frames
around itself (held-out scene, seed 1: 9 frames in a row 212-237 px off). The tracker now lets
the detector verify each pose by the network's own scores where the pose shows its parts
(:meth:`pose.corners.CornerDetector.support`, :data:`pose.corners.MIN_SUPPORT`): on the networks of
``runs/table1_v6`` (seeds 0 and 1, none and ALCN) the sum over #1-#8 of their mean % rose from 551 to 639
(#3 57.5 -> 81.7, #5 8.3 -> 36.7, #8 34.2 -> 55.0), on the held-out scene's 6 networks from 52.2 to
67.2%; Table 1 with it (3 seeds, ``runs/table1_v7``): none 98.9 85.6 84.4 92.2 40.0 94.4 88.9 61.1,
ALCN 98.9 84.4 84.4 93.3 37.8 98.9 100 57.8, the held-out scene 71.1 and 63.3% (``runs/heldout_v7``).
Tried on top of it, not kept (one or two seeds each, sums over #1-#8 or the held-out
scene's mean): a light of its own on each face of half of the copies (a factor in 0.5-1.5, as a
directional light changes a Lambertian face) and a cast shadow on half of them (a soft band at
0.3-0.8 of the light): none 640 / 560 and ALCN 670 / 630 for seeds 0 / 1, against 613 / 633 and
663 / 647 without (ALCN's #5 83.3 then 40.0); after a rejected pose, RANSAC again without its
inliers (up to 3 times): 63.9; 8 candidates per part in the whole frame: 60.0; candidates of the
whole frame at a second scale (0.6) too, for the close views: 66.7; a first pose from 4 inliers
instead of 5 (verified as the others): 61.7, and 637.5 over #1-#8 (seeds 0 and 1) against 639.

What is still lost is mostly the first frames of a sequence, before any pose: a few right
candidates among the 130 of the whole frame, too few for RANSAC's 5-inlier consensus, while the
true pose's support stands out (#2, ALCN seed 2, frames 3-5: 0.42, 0.36, 0.59), and 2000 draws
of 4 candidates, RANSAC's minimal set and its check, found no right pose. :meth:`pose.corners.CornerDetector.propose` scores the P3P poses of 2000 candidate
triples by the support itself, and a pose proposed then searched around must reach 0.3
(:data:`pose.corners.MIN_PROPOSAL_SUPPORT`) and stand out: on every frame of #2, #3, #5 and #8
(ALCN seed 1 and none seed 0 of ``runs/table1_v7``, 240 frames) the best pose was right at 125;
with a support of at least 0.3, and every pose farther than 20 px scoring at most 0.75 / 0.85 /
0.9 / any of it (:data:`pose.corners.MAX_RIVAL_RATIO`), 97 / 105 / 114 / 123 right and 6 / 11 /
27 / 65 wrong were kept. The sum over #1-#8 of the mean % of the 3 seeds (the networks of
``runs/table1_v7`` and ``runs/table1_v7_lite`` again, ``runs/proposals``), without proposals / with
a ratio of 0.75 / 0.85 (the default): none 645.6 / 661.1 / 667.8, DoG 674.4 / 680.0 / 690.0,
Tan-Triggs 611.1 / 618.9 / 627.8, ALCN 655.6 / 663.3 / 667.8, lite ALCN 627.8 / 632.2 / 653.3; at
0.85 none of the 15 networks posed fewer frames right on any of the 8 sequences. The held-out scene's 6
networks posed the same frames: there the true pose of the lost first frames scores 0.10-0.31
(ALCN seed 0), no more than wrong poses elsewhere (0.28-0.38). Without the rival test, and with
the pose searched around the proposal verified at 0.15 as the others, ALCN seed 0 fell from 53.3
to 40.0% of that scene's #1. A proposal costs about 50 ms, on lost frames only.

Tried after the proposals, not kept: each face the view shows, and the rest of the frame, relit
by a gain of its own on half of the copies (log-uniform in 1/8-4, in linear light, then clipped:
#5's grazing light darkens the faces turned away from it to about a tenth and burns out those it
faces). Sums over #1-#8 for seeds 0 / 1 / 2: none 670.0 / 606.7 / 726.7 and ALCN 686.7 / 656.7 /
590.0 (without: 650.0 / 646.7 / 706.7 and 670.0 / 670.0 / 663.3), ALCN's #1 86.7% with seed 2; the
held-out scene none 73.3 / 43.3 / 80.0 and ALCN 40.0 / 56.7 / 50.0% (without: 56.7 / 66.7 / 90.0
and 53.3 / 60.0 / 76.7). The parts of #5 found among the candidates hardly moved (ALCN seed 0, as
the best candidate / among them: 19 / 32% against 13 / 25%).

Tried after the refinement, not kept (``runs/turn``): where the poses are lost under the training
light (``--training-light``), the test viewpoint lies in a gap of the training orbit (#5 frames
17-23: azimuths -105..-83 deg, between training views at -111 and -84; #3 frames 11-18: 20 deg
lower than the training views there; the held-out scene's first frames: 25-30 deg lower, and
closer), or the box stands on a table unlike any background (#5: a green checkerboard in
perspective). Two augmentations, seed 0 each, one torch thread, measured by the recall (visible
parts among the candidates within 4 px, every second frame of #1-#8 lit / under the training
light; the held-out scene's #1) and the poses (sums over #1-#8, lit / training light; the
held-out #1), ALCN then none: the networks of ``runs/table1_v7`` 52.9 / 62.4 and 52.0 / 64.9% of
the parts, held-out 39.7 and 42.2%, poses 686.7 / 726.7 and 690.0 / 773.3, held-out 56.7 and
63.3%. (a) :func:`pose.corner_data.novel_view` taking the faces its view shows too little from
the training view that shows them largest, so that the camera can turn farther (up to 8 deg as
now: 51.6 / 60.9 and 51.6 / 65.3%, held-out 40.1 and 35.0%, poses 600.0 / 693.3 and 686.7 /
736.7, held-out 73.3 and 50.0%; up to 45 deg: 48.7 / 57.7 and 49.9 / 62.4%). (b) On 40% of the copies the background
replaced by a texture laid on the table's plane in perspective (the data engine's textures at
0.5-2 mm per texel, a flat one above the horizon): 53.2 / 62.7 and 53.3 / 67.1%, held-out 37.9
and 43.7%, poses 660.0 / 743.3 and 673.3 / 763.3, held-out 73.3 and 63.3%; with (a) at 45 deg
51.7 / 60.6 and 52.8 / 65.1%, held-out 37.2 and 38.6%. No change moved the recall by more than
the seeds do, nor the poses. Nor did two changes of the scale at which the network runs,
measured on the same networks (``runs/table1_v7``, none and ALCN, seeds 0 and 1, sums over
#1-#8; without: 690.0, 686.7, 696.7, 663.3): while tracking, a scale that follows the predicted
pose's distance ``d``, ``0.75 * clip(d / d_ref, 0.7, 1)``, with ``d_ref`` the training views'
median (593 mm: 686.7, 683.3, 623.3, 683.3) or their 10th percentile (527 mm: 716.7, 680.0,
596.7, 673.3); a frame lost without a prediction searched again at 0.6 (693.3, 636.7, 626.7,
670.0; the held-out scene's 6 networks posed the same frames).

The training orbit (``runs/orbit``, ``runs/table1_v9``): where the held-out scene's first frames
are lost, they are 25-30 deg below the training views at their azimuths, and the training loop
(then one loop whose elevation rises and falls once over 330 deg, as the test trajectories' does)
sees each stretch of azimuth from one height only. The data engine now renders a second loop
whose elevation rises and falls three times (:data:`alcn_cv.data.pose.TRAIN_SWEEPS`, 60 views
with ``--frames 30``). One torch thread, ALCN then none; sums over #1-#8 lit / under the training
light, the held-out #1, the parts found (lit / training light / held-out); the v7 networks (one
loop) lit 686.7, 663.3, 663.3 and 690.0, 696.7, 703.3, held-out 56.7, 63.3, 83.3 and 63.3, 76.7,
90.0%, parts (seed 0) 52.9 / 62.4 / 39.7 and 52.0 / 64.9 / 42.2%. The second loop alone, seeds
0-2 (30 views: three sweeps instead of one): 740.0 / 720.0, 700.0 / 733.3, 736.7 / 726.7 and 696.7
/ 760.0, 733.3 / 733.3, 736.7 / 770.0; held-out 70.0, 33.3, 56.7 and 83.3, 80.0, 20.0%; parts 51.5
/ 61.7 / 33.7 and 52.3 / 65.6 / 36.6%: the held-out scene's first frames found, its frames 5-15
(azimuths 170..-110, elevations 49-63 deg) lost instead. Five sweeps (seeds 0, 1): 663.3, 650.0
and 650.0, 663.3 lit (#5 10-13%), held-out 76.7, 56.7 and 96.7, 76.7%. Three sweeps over 60
views (seed 0): 706.7 and 713.3 lit, held-out 36.7 and 90.0%, its parts 34.3 and 35.7%; one
sweep over 60 views: held-out 56.7 and 66.7%, parts 41.5 and 40.1%; three sweeps with 4000 steps:
740.0 and 740.0 lit, held-out 53.3 and 80.0%. Both loops (the first two sets of views merged),
seeds 0-2: held-out 93.3, 83.3, 76.7 and 83.3, 73.3, 80.0%, parts 41.2 and 38.2% on average;
seed 0 753.3 / 746.7 and 703.3 / 780.0, parts 57.1 / 66.6 and 56.1 / 69.4%. Rendered by the data
engine (the second loop's noise drawn anew; ``runs/table1_v9``, sums over #1-#8 of the mean of 3
seeds, against the one-loop networks of ``runs/refine_v8``): none 721.1 (696.7; every seed higher:
746.7, 700.0, 716.7), DoG 690.0 (696.7), Tan-Triggs 655.6 (631.1), ALCN 695.6 (671.1; every seed
higher: 720.0, 673.3, 693.3); under the training light none 765.6 (765.6), ALCN 733.3 (722.2); the
held-out scene 76.7 +- 11.9% without normalization (76.7) and 76.7 +- 12.5% with ALCN (67.8).
Not kept (one loop): a context branch beside the network's head (``runs/turn/ctx.py``: 32
channels, dilated 3x3 convolutions at 2 and 4 cells, so a cell sees about 80 instead of 32
pixels; crops of 16 cells), ALCN then none, seeds 0 / 1: 676.7 / 640.0 and 700.0 / 663.3 lit, held-out (seed 0) 46.7 and
73.3%, parts 52.2 / 61.6 / 39.0 and 56.1 / 67.0 / 37.2% (seed 0).

Not kept (two loops, ``runs/joint``, seeds 0-2, one torch thread): the gain Normalizer trained
jointly with the network, as the paper trains ALCN with its detector (Eq. 2). Each crop is
normalized by :class:`~alcn_cv.nets.gain.GainNormalizer` from its intensities 48 pixels around
it, with the divisive floor of its whole frame. The Normalizer starts from the shipped file and
learns at a tenth of the network's rate (3e-4). 2000 steps take 6.5-8 min a network, against
2.6-3.6 min with the Normalizer frozen on the same crops. Lit / training light sums over #1-#8:
jointly 716.7 / 750.0, 703.3 / 743.3, 740.0 / 753.3 (mean 720.0 / 748.9, #5 45.6); frozen
690.0 / 763.3, 763.3 / 716.7, 676.7 / 746.7 (710.0 / 742.2, #5 43.3). Held-out #1: 66.7, 96.7,
76.7 and 66.7, 96.7, 66.7%. Without normalization the same data give 721.1 / 765.6, held-out
76.7%. The joint networks beat the frozen ones by less than the seeds' spread, and do not beat
the networks without normalization.
Not kept either, the networks of ``runs/table1_v9`` re-evaluated (``runs/robust``): a last refinement of
each pose under a Cauchy loss of scale 1.5 px (``scipy.optimize.least_squares`` on RANSAC's
inliers). It targets the frames posed 5-7 px off: there one or two inliers lie 9-11 px from
the truth, while the parts found within 4 px of it give 1-2.5 px. It fixed two such frames of
the held-out scene (none, seed 2: 83.3 -> 90.0%). Lit sums of none, seeds 0-2, and ALCN, seed
0: 720.0, 690.0, 716.7, 716.7 against 746.7, 700.0, 716.7, 720.0 without it. A pose a few
pixels different gates the next frames elsewhere, and that decided more frames than the
refinement did.
Nor twice the copies per view (23 instead of 11, ``runs/copies``; 3.3-4.4 min a network). Held-out
#1 without normalization: 86.7, 86.7, 83.3% against 86.7, 60.0, 83.3. With ALCN: 73.3, 73.3,
66.7% against 60.0, 90.0, 80.0. Seed 0, lit / training light: none 743.3 / 756.7 against 746.7 /
763.3, ALCN 733.3 / 770.0 against 720.0 / 750.0.

The intensity change of the copies (``a I + b``, :func:`pose.corner_data.build_frames`) is what
makes the network without normalization robust: trained without it (``--no-intensity``, 3 seeds,
``runs/nointensity``) it poses 31.1, 0 and 13.3% of #4, #5 and #8 (98.9 and 90.0 / 63.3 / 73.3
with it), while the networks behind ALCN, the DoG or Tan-Triggs keep most of theirs (ALCN 93.3 /
34.4 / 53.3); with two loops (``runs/table1_v10/ni``) none 38.9 / 0 / 37.8 and ALCN 98.9 / 46.7 /
77.8. The README's Table 1 has every row, and the same sequences under the training light
(``alcn data pose --training-light``).

The 8-corner design before it, measured on the data engine's sequences (30 frames each, no
normalization, % of poses within 5 px on #1 / #3; 2-core CPU shared with other jobs, load 8-11):
16/32/64 channels without batch
normalization, 1500 steps: 6.7 / 0 (the network scored the right corner highest at only 13% of
the visible corners of #1); with it, 1000 steps: 36.7 / 0; 1500 steps on 12 copies per view
instead of 8 (milder homographies, new backgrounds 80% instead of 50%): 53.3 / 46.7; the same
network with 5 candidates per corner above 0.05 in the whole frame (instead of 3 above 0.2) and
4 inliers for a pose near the prediction: 86.7 / 43.3; crops of 12x12 cells, lr 3e-3, 1200
steps (155 s): 80.0 / 66.7; wider (24/48 channels, 128; 640 s, half the speed): 60.0 / 86.7.
Once the box is found, the poses are within 1-3 px; what is lost is the first frames (no four
right corners among the candidates of the whole frame) and views where two or three corners
are missed (about 25-45% of the visible corners of #1 score below 0.2 where they are). The
former defaults, 1000 steps of 16/32/64 channels (48-250 s): #1 50.0 +- 2.7 over 3 seeds; 3000 steps: 63.3 / 60.0, and on
the training light of a scene rendered with another seed (``alcn data pose --seed 1``, its own
training sequence) 3.3% after 1000 steps, 13.3% after 3000.

Why, measured on the raw detections of #1 against the true corners before PnP (seed 0, no
normalization; a detection is right within 5 px of the full frame): the right candidate was the
best of its corner at 41% of the visible corners, among the 5 candidates at 65%, among the 2
within 20 px of the true pose's projection at 81%; the right ones were placed within 1.2 px
(median; 90% within 3.2 px), the 36 wrong candidates per frame scored lower (median 0.26
against 0.55). On the training views themselves only 65% / 78%: the network underfitted, and a
recall this low, not localisation, false positives or the solver, left PnP without 5 right
corners. Wider fully connected layers with one more (128 channels, ``mixing=1``, 2000 steps,
151 s): 96% on the training views but 55% / 70% / 79% on #1 (86.7% of the poses): now the
network does not generalize to the test trajectory's viewpoints, and neither more steps (5000:
57 / 70 / 76, 63.3%) nor wider convolutions (24/48: 56 / 76 / 81, 63.3%, twice the time) change
that. Copies seen from new viewpoints (:func:`pose.corner_data.novel_view`: each face of the box
warped by its own plane's homography, 60% of the copies) raised it to 61 / 78 / 90 and 93.3%
of the poses (the defaults; the two lost frames are the first two, where 4 of the 5 right
corners needed were found); 90% of 23 copies and 3000 steps: 62 / 78 / 85, 93.3%. Table 1 with
the defaults, 3 seeds (290 s per training at load 5, 580-690 s at load 10-12): #1 86.7 +- 14.4
without normalization, 84.4 +- 15.5 with the DoG, 81.1 +- 16.4 with ALCN; one seed of each
reached 100%, the others lost their first 2-9 frames (4 right corners among the candidates of
the whole frame where 5 are needed; letting a 4-inlier start be confirmed by the next frame's
gated search won 30% of #1 on one seed but lost up to 50% of a sequence on others, through
wrong starts).

The held-out scene (``alcn data pose --seed 1``, its own training sequence, #1 under the training
light), measured with ``alcn pose corner-recall`` (found as the best candidate / among the 5 /
in the gates of the true pose; one network, seed 0): the training views 83 / 100 / 100%, #1 only
26 / 41 / 68% (43.3% of the poses). ``alcn pose eval --seeds 3``: 6.7 +- 9.4% of #1's poses (20,
0, 0; the poses swing with the few corners found, the recall does not: 21-24 / 39-43 / 62-64%),
where the 3 networks of the first scene pose 86.7 +- 14.4% of its #1 (93.3, 100, 66.7) and find
60-62 / 78 / 81-90% of its corners. Not the viewpoints: #1's distances (431-673 mm), elevations
(24-64 deg) and in-plane rotations (-14..3 deg) lie within the training sequence's (455-719,
24-68, -16..10), and #1's trajectory rendered on the training scene's table and clutter gives
65 / 85 / 91% (73.3% of the poses). The table: with everything
but the box grey 74 / 91 / 92%, without the clutter on #1's own table 29 / 45 / 70%; #1's table is
a bright stone texture (mean grey level 151 against the training table's 67 and the box's 155),
and at 43% of #1's visible corners the background class outscores the corner's (14% on grey).
The network is not background-invariant: random-texture backgrounds, as 80% of the copies get,
take its training views down to 64 / 79 / 84%. Tried on that scene, one seed each, none finding
more than 49% of #1's corners among the candidates nor more than the 43.3% of the poses: 8 sets of
fresh copies drawn in turn (8 times the backgrounds; 22 / 43 / 66%, 30.0% of the poses), the
same with new backgrounds on every copy (25 / 46 / 70, 20.0) or with 4000 steps (31 / 45 / 66,
6.7), a corner weight of 4 (26 / 39 / 64, 16.7), an intensity change of the background alone (a
table as bright as the box) on half or all of the copies (27 / 49 / 66, 3.3; 25 / 44 / 64, 6.7),
wider layers with 4 sets of copies (24/48 channels: 21 / 43 / 63, 0; a fully connected layer of
256: 25 / 47 / 65, 20.0), corner cells within 6 px (neg. 9; 21 / 38 / 59), frames at scale 0.75
(less table in a window; 17 / 44 / 81, 20.0: only the gated search gains), a DoG (1/2 px) in front
(20 / 35 / 61); 10 candidates per corner above 0.02 find 50% but pose 13.3%.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from alcn_cv.enhance.alcn import pin_default_model
from alcn_cv.errors import InputError
from pose.box import DIVISIONS, NUM_CORNERS, box_parts
from pose.corner_data import SCALE, CornerFrames, build_frames, build_image_frames
from pose.corners import FORMAT_NAME, FORMAT_VERSION, PAD, STRIDE, WINDOW

logger = logging.getLogger(__name__)

#: Training steps of :func:`train_corners` and the crops per step (the module docstring says why).
ITERATIONS = 4000
BATCH_SIZE = 64


def export_onnx(net, out: str | Path, meta: dict[str, Any]) -> Path:
    """Write the corner network as ONNX with ``meta`` in its ``metadata_props`` (atomically).

    Graph: input ``"image"`` ``(1, 1, H, W)`` float32 (the normalized, downscaled frame padded
    by 16 pixels on every side), output ``"outputs"`` ``(1, 25, (H-32)//4+1, (W-32)//4+1)``.
    """
    import io as _io
    import warnings

    import torch

    from alcn_cv.io import atomic_write
    from alcn_cv.train.export import OPSET, with_metadata

    out = Path(out)
    if out.suffix != ".onnx":
        raise InputError(f"the ONNX output must end in .onnx, got {out}")
    buffer = _io.BytesIO()
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # see alcn_cv.train.export
        torch.onnx.export(net.eval(), (torch.rand(1, 1, WINDOW + 12, WINDOW + 20),), buffer,
                          input_names=["image"], output_names=["outputs"],
                          dynamic_axes={"image": {2: "height", 3: "width"}, "outputs": {2: "gh", 3: "gw"}},
                          opset_version=OPSET, dynamo=False)
    data = with_metadata(buffer.getvalue(), meta)
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(out, data)
    logger.info("corner detector written to %s (%d kB)", out, len(data) // 1024)
    return out


def sample_crops(frames: CornerFrames, rng: np.random.Generator, n: int, cells: int, near_corner: float = 0.7
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``n`` random crops of ``cells x cells`` output cells: images ``(n, 1, S, S)`` with
    ``S = 32 + 4 (cells - 1)``, labels ``(n, cells, cells)``, offsets ``(n, 2, cells, cells)`` and
    owners ``(n, cells, cells)``; a share ``near_corner`` of them contains a visible corner cell."""
    size = WINDOW + STRIDE * (cells - 1)
    _, gh, gw = frames.labels.shape
    if gh < cells or gw < cells:
        raise InputError(f"frames of {gh}x{gw} output cells are smaller than the crops ({cells}x{cells})")
    images = np.empty((n, 1, size, size), np.float32)
    labels = np.empty((n, cells, cells), np.int64)
    offsets = np.empty((n, 2, cells, cells), np.float32)
    owner = np.empty((n, cells, cells), np.int64)
    for b in range(n):
        f = int(rng.integers(len(frames.labels)))
        hits = np.argwhere(frames.labels[f] > 0)
        if len(hits) and rng.random() < near_corner:
            ci, cj = hits[rng.integers(len(hits))]
            i0 = int(np.clip(ci - rng.integers(cells), 0, gh - cells))
            j0 = int(np.clip(cj - rng.integers(cells), 0, gw - cells))
        else:
            i0, j0 = int(rng.integers(gh - cells + 1)), int(rng.integers(gw - cells + 1))
        images[b, 0] = frames.images[f, i0 * STRIDE: i0 * STRIDE + size, j0 * STRIDE: j0 * STRIDE + size]
        labels[b] = frames.labels[f, i0:i0 + cells, j0:j0 + cells]
        offsets[b] = frames.offsets[f, :, i0:i0 + cells, j0:j0 + cells]
        owner[b] = frames.owner[f, i0:i0 + cells, j0:j0 + cells]
    return images, labels, offsets, owner


def jitter_crops(images: np.ndarray, rng: np.random.Generator, *, contrast: float = 1.5, ramp: float = 0.4,
                 offset: float = 0.3, noise: float = 0.15) -> np.ndarray:
    """Jitter the network's input after the normalizer, in place: each crop ``x`` of ``images``
    ``(n, 1, S, S)`` float32 (standardized, as :func:`sample_crops` returns them) becomes
    ``exp(log a + gx u + gy v) x + b + n``, ``u, v`` in [-1, 1] across the crop: a contrast ``a``
    log-uniform in ``[1 / contrast, contrast]``, a gain ramp (``gx, gy`` uniform in ``+-ramp``), an
    offset ``b`` uniform in ``+-offset`` and Gaussian noise of a standard deviation uniform in
    ``[0, noise]``. The copies' intensity change ``a I + b`` gives the network without normalization
    this variety; a normalizer in front takes most of it away again (why: :mod:`pose.corner_train`)."""
    size = images.shape[-1]
    u = np.linspace(-1, 1, size, dtype=np.float32)
    for b in range(len(images)):
        log_a = rng.uniform(-np.log(contrast), np.log(contrast))
        gx, gy = rng.uniform(-ramp, ramp, 2)
        gain = np.exp(log_a + gx * u[None, :] + gy * u[:, None]).astype(np.float32)
        images[b, 0] = (gain * images[b, 0] + rng.uniform(-offset, offset)
                        + rng.normal(0, rng.uniform(0, noise), (size, size)).astype(np.float32))
    return images


def corner_loss(out, labels, offsets, owner, corner_weight: float = 2.0, offset_weight: float = 1.0):
    """Cross-entropy of the cells (``-1`` ignored, part classes weighted by ``corner_weight``)
    plus ``offset_weight`` times the smooth L1 loss of the offsets of the owned cells; torch tensors
    as :func:`sample_crops` returns them and the network's ``(b, 3n + 1, cells, cells)`` output."""
    import torch
    import torch.nn.functional as F

    num_parts = (out.shape[1] - 1) // 3
    k = num_parts + 1
    weight = torch.full((k,), corner_weight, dtype=out.dtype, device=out.device)
    weight[0] = 1.0
    loss = F.cross_entropy(out[:, :k], labels, weight=weight, ignore_index=-1)
    own = owner >= 0
    if own.any():
        pred = out[:, k:].reshape(out.shape[0], num_parts, 2, *out.shape[2:])  # (b, n, 2, c, c)
        b, i, j = torch.nonzero(own, as_tuple=True)
        chosen = pred[b, owner[b, i, j], :, i, j]  # (m, 2)
        loss = loss + offset_weight * F.smooth_l1_loss(chosen, offsets[b, :, i, j], beta=0.1)
    return loss


def fit(net, frames: CornerFrames, *, iterations: int = ITERATIONS, batch_size: int = BATCH_SIZE, cells: int = 16,
        lr: float = 2e-3, seed: int = 0, progress: bool = True, device: str | None = None, jitter: bool = False,
        **loss_kw: Any) -> dict[str, Any]:
    """Train ``net`` on crops of ``frames`` (Adam, the learning rate divided by 10 for the last
    quarter) on ``device`` (a torch device; ``None``: CUDA where torch sees it, else the CPU),
    each crop jittered by :func:`jitter_crops` where ``jitter``, then leave it on the CPU; returns
    the mean loss of the first 10 steps and of the last quarter (at most 100) and the device.
    Deterministic for a ``seed`` and a number of torch threads on the CPU (other
    threads, and a GPU, sum in another order and give another network)."""
    import torch

    from alcn_cv.nets.device import torch_device

    device = torch_device(device, "the corner network's device")
    net.to(device)
    rng = np.random.default_rng(seed)
    jitter_rng = np.random.default_rng(seed + 1000)  # its own stream: the crops drawn do not depend on ``jitter``
    optimiser = torch.optim.Adam(net.parameters(), lr=lr)
    schedule = torch.optim.lr_scheduler.MultiStepLR(optimiser, [int(0.75 * iterations)], 0.1)
    net.train()
    losses = []
    for _ in tqdm(range(iterations), desc="corners", unit="step", disable=not progress, leave=False):
        crops = sample_crops(frames, rng, batch_size, cells)
        if jitter:
            jitter_crops(crops[0], jitter_rng)
        images, labels, offsets, owner = (torch.from_numpy(a).to(device) for a in crops)
        loss = corner_loss(net(images), labels, offsets, owner, **loss_kw)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        schedule.step()
        losses.append(loss.item())
    net.to("cpu").eval()
    return {"first_loss": float(np.mean(losses[:10])),
            "final_loss": float(np.mean(losses[-max(1, min(100, iterations // 4)):])), "device": str(device)}


def train_corners(sequence_dir: str | Path, corners: np.ndarray, out: str | Path, *, normalizer: str = "none",
                  units: str = "mm", obj_id: int | None = None, scale: float = SCALE,
                  channels: tuple[int, int] = (16, 32), hidden: int = 128, mixing: int = 1,
                  iterations: int = ITERATIONS, divisions: int = DIVISIONS,
                  batch_size: int = BATCH_SIZE, cells: int = 12, lr: float = 3e-3, seed: int = 0, progress: bool = True,
                  device: str | None = None, jitter: bool = False, **frames_kw: Any) -> Path:
    """Train the corner detector on a registered sequence and export it to ``out`` (``.onnx``).

    Args:
        sequence_dir: a registered training sequence (anything :func:`pose.sequence.load_sequence`
            reads; the BOP ``mask_visib`` is used when present).
        corners: ``(8, 3)`` box corners in the object (world) frame, in ``units``.
        out: the ``.onnx`` file to write.
        normalizer: the normalizer applied first (stored in the file; tracking uses the same).
        scale: downscaling of the frames (stored in the file).
        channels, hidden, mixing: :class:`pose.corner_net.CornerNet`'s.
        iterations, batch_size, cells, lr, seed, device, jitter: see :func:`fit` (``cells``: the
            crops' side in output cells).
        divisions: the parts found, :func:`pose.box.box_parts` ``(corners, divisions)``.
        **frames_kw: see :func:`pose.corner_data.build_frames` (``copies``, ...).

    Returns:
        The written path.
    """
    from pose.sequence import load_sequence

    corners = np.asarray(corners, np.float64)
    if corners.shape != (NUM_CORNERS, 3) or not np.isfinite(corners).all():
        raise InputError(f"corners must be a finite (8, 3) array, got shape {corners.shape}")
    if not 0 < scale <= 2:
        raise InputError(f"scale must be in (0, 2], got {scale}")
    if iterations < 1 or batch_size < 1 or not lr > 0:
        raise InputError(f"need iterations >= 1, batch_size >= 1 and lr > 0, got {iterations}, {batch_size}, {lr}")
    t0 = time.perf_counter()
    seq = load_sequence(sequence_dir, obj_id=obj_id)
    frames = build_frames(seq, corners, normalizer, scale=scale, divisions=divisions, seed=seed, **frames_kw)
    return fit_and_export(frames, box_parts(corners, divisions), corners, out, normalizer=normalizer, units=units,
                          scale=scale,
                          source=str(sequence_dir), data_seconds=time.perf_counter() - t0, views=len(seq.views),
                          channels=channels, hidden=hidden, mixing=mixing, iterations=iterations,
                          batch_size=batch_size, cells=cells, lr=lr, seed=seed, progress=progress, device=device,
                          jitter=jitter)


def fit_and_export(frames: CornerFrames, parts: np.ndarray, corners: np.ndarray, out: str | Path, *,
                   normalizer: str, units: str,
                   scale: float, source: str, data_seconds: float, views: int, channels: tuple[int, int] = (16, 32),
                   hidden: int = 128, mixing: int = 1, iterations: int = ITERATIONS, batch_size: int = BATCH_SIZE,
                   cells: int = 12, lr: float = 3e-3, seed: int = 0, progress: bool = True,
                   device: str | None = None, jitter: bool = False) -> Path:
    """Train a :class:`pose.corner_net.CornerNet` for ``parts (n, 3)`` on ``frames`` (:func:`fit`)
    and export it with its metadata (:func:`export_onnx`); the rest as :func:`train_corners`'s."""
    import torch

    from pose.corner_net import CornerNet

    t1 = time.perf_counter()
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        net = CornerNet(len(parts), channels, hidden, mixing)
        cells = min(cells, *frames.labels.shape[1:])
        fit_info = fit(net, frames, iterations=iterations, batch_size=batch_size, cells=cells, lr=lr, seed=seed,
                       progress=progress, device=device, jitter=jitter)
    meta = {"format": FORMAT_NAME, "version": FORMAT_VERSION, "normalizer": pin_default_model(normalizer), "scale": scale,
            "input_mean": frames.input_mean, "input_std": frames.input_std,
            "parts": np.asarray(parts, np.float64).tolist(), "corners": np.asarray(corners, np.float64).tolist(),
            "units": units, "window": WINDOW, "stride": STRIDE,
            "pad": PAD, "config": net.config, "source": source,
            "fit": {"frames": len(frames.labels), "views": views, "iterations": iterations,
                    "batch_size": batch_size, "cells": cells, "lr": lr, "seed": seed, "jitter": jitter,
                    "data_seconds": data_seconds,
                    "train_seconds": time.perf_counter() - t1, **fit_info}}
    path = export_onnx(net, out, meta)
    logger.info("corner detector (%s): %d frames in %.1f s, training %.1f s on %s, final loss %.3f", normalizer,
                len(frames.labels), data_seconds, time.perf_counter() - t1, fit_info["device"], fit_info["final_loss"])
    return path


def train_image_corners(gray: np.ndarray, uv: np.ndarray, parts: np.ndarray, corners: np.ndarray, out: str | Path, *,
                        normalizer: str = "none", units: str = "mm", scale: float = 0.5, source: str = "",
                        copies: int = 59, seed: int = 0, progress: bool = True, **fit_kw: Any) -> Path:
    """Train the detector of parts of one image (a planar target's, :mod:`pose.planar`) and export it.

    Args:
        gray: the training image, uint8.
        uv: ``(n, 2)`` the parts' pixels in it.
        parts: ``(n, 3)`` the parts in the object frame (``units``).
        corners: ``(8, 3)`` the object's box (the pose solver's outline; a flat one for a plane).
        out: the ``.onnx`` file to write.
        normalizer, scale, seed: as :func:`train_corners`'s.
        copies: augmented copies of the image (:func:`pose.corner_data.build_image_frames`).
        **fit_kw: :func:`fit_and_export`'s ``iterations``, ``channels``, ...
    """
    parts = np.asarray(parts, np.float64)
    if parts.ndim != 2 or parts.shape != (len(uv), 3) or not np.isfinite(parts).all():
        raise InputError(f"parts must be a finite (n, 3) array for the n = {len(uv)} pixels, got shape {parts.shape}")
    t0 = time.perf_counter()
    frames = build_image_frames(gray, uv, normalizer, scale=scale, copies=copies, seed=seed)
    return fit_and_export(frames, parts, corners, out, normalizer=normalizer, units=units, scale=scale, source=source,
                          data_seconds=time.perf_counter() - t0, views=1, seed=seed, progress=progress, **fit_kw)


def main(sequence_dir: str | Path, out: str | Path, *, box_ply: str | Path | None = None,
         model: str | Path | None = None, **kwargs: Any) -> Path:
    """``alcn pose train-corners``: the box corners from ``box_ply`` (a cuboid mesh, mm) or a part
    model (``model``, its units), then :func:`train_corners`."""
    from pose import model as part_model

    if (box_ply is None) == (model is None):
        raise InputError("give the box as either box_ply (a .ply cuboid) or model (a part model .npz)")
    if box_ply is not None:
        corners, units = part_model.read_box_corners(box_ply), "mm"
    else:
        pm = part_model.load(model)
        corners, units = pm.corners, pm.units
    return train_corners(sequence_dir, corners, out, units=units, **kwargs)
