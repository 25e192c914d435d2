"""The map-merging benchmark behind ``mrslam bench merge``.

Pairs (made the way the paper made its pairs)
---------------------------------------------
The project's simulator drives one robot (:class:`agents.wander.WanderPolicy`, onboard
:class:`~mrslam_env.slam.slam.RobotSlam` in ``slam`` mode) from a random reachable start with
a random heading; each run's map is in its own map frame (= its start pose). Several such
runs per world are independent: a pair is two of them, and its ground truth is
``map1_from_map2 = inverse(start1) ∘ start2`` (true world start poses). Each run's map is
saved at several checkpoints (env steps), so one run gives maps of several sizes; pairs take
any checkpoint of two *different* runs (pairs may share a run, preferably not). Starts are
half spread out (farthest-point sampling: far-apart starts give the no-overlap pairs) and
half uniformly random. The default set (6 worlds x 8 runs x 1500 steps) takes about
70 s to simulate on one core. The truth is exact for the map frames; the maps themselves
carry their SLAM's drift (a few centimetres), as real pairs do.

The **overlap** of a pair is computed from the ground truth: both maps' known cells (FREE
or OCCUPIED) are resampled (nearest cell) onto one raster at the maps' resolution (the
world frame at generation, map 1's frame in :func:`mrslam_env.evaluation.true_overlap`), and
``overlap = |known1 ∧ known2| / min(|known1|, |known2|)``: the share of the smaller map's
known area that the other map also knows.

Pairs are chosen to fill overlap bins (default ``[0.2, 0.35)``, ``[0.35, 0.5)``,
``[0.5, 0.65)``, ``[0.65, 0.85)``) over the worlds (every built-in scenario and two
procedural layouts) in turn, plus **no-overlap** pairs (``overlap < 0.02``): about a fifth
of the set. Generated pairs are cached as ROS map files plus ``manifest.json`` in
``<cache>/<key>/`` where the key holds :data:`GENERATOR_VERSION`, the pair count, the seed
and a digest of the whole :class:`PairGenerationConfig`.

Real maps
---------
The worlds may be real buildings (:mod:`scenarios.worlds.real`, by name) or built from any
ROS map file (``PairGenerationConfig.maps``, cleaned by
:func:`~mrslam_env.sim.cleaning.clean_for_simulation`, labelled ``map:<stem>``); pairs are
generated the same way. With ``native_resolution`` the SLAM runs at the source map's
resolution (0.02 m for ``aws_warehouse``) instead of its default 0.05 m. ``mrslam bench
merge`` runs the built-in set (unchanged key) and a real-building set
(:data:`~scenarios.bench.merge.pairs.REAL_WORLDS`, native resolution) side by side and
reports them per world family; on every set but the built-in one ``ours`` also runs on
variants of each pair (map 2 padded to 4000² cells, with an origin yaw, at another
resolution; :mod:`scenarios.bench.merge.run`), and each pipeline row records whether the
truth was among its candidates (the proposal recall).

Pairs cut from the real map files
---------------------------------
``mrslam bench merge --set cuts`` (:mod:`scenarios.bench.merge.cuts`) cuts pairs from the six
real map files themselves at their native resolution (ragged walls, clutter, up to about
1,000 cells a side): two windows of one map, map 2 turned by a random angle about a random
point and re-rasterised (the truth is exact), overlaps stratified like the simulated sets,
plus disjoint windows and windows of two different buildings (both without overlap). The
same methods, rows and reports run on them; the twin test needs a world and is skipped.

Methods
-------
Each is ``(m1, m2, rng) -> map1_from_map2 (3,) or None`` (None = "no confident merge"):

``ours``         :func:`mrslam_env.merge.pipeline.merge_maps` (virtual robot + MCL +
                 random-walk refinement, docs/design.md §5)
``random-walk``  Birk & Carpin alone: :func:`mrslam_env.merge.refine.refine_random_walk`
                 from several random initial transforms, best psi kept, accepted when its
                 acceptance index reaches :attr:`RandomWalkBaselineConfig.acceptance_threshold`
``features``     ROS ``multirobot_map_merge`` (:mod:`scenarios.bench.merge.features`; needs the
                 ``baselines`` extra, i.e. OpenCV)
``ours-nocrop``  ours with ``MergeConfig(crop_to_known=False)`` (the default until issue 21)
``ours-cascade`` ours with ``MergeConfig(cascade=True)`` (cheap proposals judged first; off by
                 default, see docs/decisions.md)
``hough``        Carpin's Hough-spectrum merger (:mod:`scenarios.bench.merge.hough`); it
                 answers every pair

A method whose module is missing is reported as skipped, not as an error.

Scoring
-------
Translation error ``|t_est - t_true|`` (m) and rotation error ``|wrap(theta_est -
theta_true)|`` (deg): :func:`mrslam_env.evaluation.relative_transform_error` at map 2's frame
origin. On an overlapping pair: **success** when both are within 0.25 m and
2°, **wrong** when a transform is returned outside that tolerance, **refused** when None.
On a no-overlap pair: **correct refusal** for None, **wrong** for any transform.

Aliasing
--------
Some pairs cannot be merged from the two maps alone: in a repetitive or symmetric building
a wrong placement fits as well as the true one. The CLI labels every overlapping pair with
:func:`scenarios.bench.merge.aliasing.aliasing`, an exhaustive placement search that uses the truth
only to tell the true placement from the rest (``clear``: the maps single out the truth;
``close``; ``misleading``), and the summary adds the success rate on the ``clear`` pairs
with overlap >= 30 %.

Some pairs no method can decide: :func:`scenarios.bench.merge.twins.world_twin` finds a second start
in the world from which map 2 would look the same (a point-symmetric building, identical
rooms), so the same two maps have a second ground truth. The CLI marks those
``undecidable`` and reports the success rate on the decidable pairs with overlap >= 30 %
and the ceiling the undecidable ones set.
"""
