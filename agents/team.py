"""The team coordinator: the paper's four interaction kinds as a state machine (design §6).

==========================  ==================================================================
state                       what the robots do
==========================  ==================================================================
``no_interaction``          each explores its own frontiers on its own map
``hypothesis_generation``   (comm up, relative pose unknown) the maps are exchanged and
                            merged by virtual robot motion; the ranked hypotheses are kept
``hypothesis_verification`` both drive to a rendezvous planned for the best untested
                            hypothesis; the peer sensor accepts or rejects it
``coordinated_exploration`` the transform is known: refined, the maps fused, both robots
                            explore the merged map and split the frontiers
==========================  ==================================================================

The coordinator uses the other robot's data only while the comm link is up: maps, poses
and sightings are exchanged then; a map received earlier stays usable (it is the robot's
copy), but is not refreshed while the link is down.

``robot_0`` holds the team frame: the merged map is in robot 0's map frame.

**N robots** (2 to 8). Each robot belongs to a group, the robots that verified transforms
connect it to, held in the frame of the group's lowest robot (its root); the common frame
is robot 0's group. Any two robots of different groups that can talk may merge their
groups' maps; the states above are then those of that pair (one merge or rendezvous at a
time, pairs that bring a robot into robot 0's frame first), told as two robots: each
robot's pose in its root's frame, the partner's peer row. An accepted (refined) transform
joins the second group to the first, its robots' transforms composed with it: a robot
joins robot 0's frame when any verified edge reaches its group. Each join is refined
against the merged map of the group it joins; once a group holds three robots or more,
all its transforms are then refined jointly (:func:`mrslam_env.merge.graph.refine_jointly`:
the overlapping pairs of own maps and the verified joins as edges of one pose graph),
not only chained. Maps are relayed through teammates (the link graph's
components). The robots in robot 0's frame explore the merged map and share frontiers;
the others explore alone. With two robots this is, step for step, the two-robot team.

**Policies.** Each robot explores with an exploration policy
(:class:`agents.policy.ExplorationPolicy`, built per robot by a factory; the frontier
explorer by default): whenever the team does not drive the robot itself it asks
``policy.act(observation, context)``. The team drives the legs to a given goal (a
rendezvous meeting point) itself, with a frontier explorer of its own used only for given
goals (:attr:`TeamCoordinator.explorers`; for the frontier explorer that is the policy
itself), so verification works whatever the policy does. What the team shares while
coordinating uses the policy's optional capabilities when it has them (module notes of
:mod:`agents.policy`): its ``target`` is shared with the teammates, ``request_replan()``
makes the later robot yield a target two chose, ``change_frame()`` carries its memory into the
common frame. A policy without a ``target`` is assigned a frontier of the merged map as
its context's ``goal`` instead (:func:`agents.explorer.team_frontier_goals`, every
``ExplorerConfig.replan_interval`` steps), which it may follow or ignore.

**Roles.** The coordinator is the state machine; the work is done by five roles, one
module each, every one a small class holding its own working state and a reference back
to the coordinator (``team``), reached as the coordinator's attributes:

``contact`` (:mod:`agents.team_contact`)
    the links, the link history (what the radio checks judge on), contact seeking;
``proposals`` (:mod:`agents.team_proposals`)
    merge attempts and sightings turned into hypotheses;
``verification`` (:mod:`agents.team_verification`)
    rendezvous planning, the meeting, the checks (peer sensor, radio, tolerances), the
    acceptance or rejection of each hypothesis;
``groups`` (:mod:`agents.team_groups`)
    groups of joined robots: joins, refinement, the fused views;
``allocation`` (:mod:`agents.team_allocation`)
    the coordinated step: teammates' positions and targets, the frontiers split.

The coordinator holds what they share: the configuration and generator, the step
snapshot (``_poses``, ``_links``, ``_reach``, the current pair's ``_last_poses``,
``_last_observations`` and ``_link``, the maps ``_maps``), the legs it drives
(``_on_goal``, :meth:`~TeamCoordinator._send`, :meth:`~TeamCoordinator._release`), the
group structure (:attr:`~TeamCoordinator.roots`, :attr:`~TeamCoordinator.frames`, written
by ``groups`` only), the state's data (:attr:`~TeamCoordinator.pair`,
:attr:`~TeamCoordinator.hypotheses`, :attr:`~TeamCoordinator.rendezvous`, the rejected
hypotheses) and the report's tallies. Every change of :attr:`~TeamCoordinator.state` is one
of its four transitions: :meth:`~TeamCoordinator._generating`,
:meth:`~TeamCoordinator._verifying`, :meth:`~TeamCoordinator._accepted` and
:meth:`~TeamCoordinator._rest`.

**One hypothesis, proposal to acceptance.** :meth:`TeamCoordinator.act` asks
``proposals`` for one (:meth:`~agents.team_proposals.Proposals.maybe_sighting`, else
:meth:`~agents.team_proposals.Proposals.maybe_generate`: a merge, ``_generating``), which
leaves the ranked hypotheses in :attr:`~TeamCoordinator.hypotheses` and hands the first
to ``verification`` (:meth:`~agents.team_verification.Verification.start`: a test in
place, a wait or a drive, ``_verifying``); every step after,
:meth:`~agents.team_verification.Verification.verify` judges it, and
:meth:`~agents.team_verification.Verification.accept` refines the accepted one, has
``groups`` join the pair's groups (:meth:`~agents.team_groups.Groups.join_pair`) and calls
``_accepted``: the team rests, coordinated once robot 0 has a teammate, and from then on
``allocation`` splits the frontiers.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from agents.explorer import ExplorerPolicy
from agents.policy import ExplorationPolicy, PolicyContext, PolicyFactory, build_policy
from agents.rendezvous import heading_allowance, in_plain_sight, radio_contradiction
from agents.robot import DEFAULT_ENV
from agents.team_allocation import Allocation, as_points
from agents.team_config import Decision, FloatArray, MapSource, TeamConfig, TeamState
from agents.team_contact import Contact, links_of
from agents.team_contact import peer_row as _row
from agents.team_contact import reachable as _reachable
from agents.team_groups import Groups
from agents.team_proposals import MergeAttempt, Proposals, distinct_hypotheses, window
from agents.team_verification import UNSEEN_STEPS, Acceptance, Verification, _Rendezvous
from mrslam_env.config import EnvConfig
from mrslam_env.geometry import compose, inverse, transform_points
from mrslam_env.gridmap import GridMap

__all__ = [
    "UNSEEN_STEPS",
    "Acceptance",
    "Decision",
    "MapSource",
    "MergeAttempt",
    "TeamConfig",
    "TeamCoordinator",
    "TeamState",
    "distinct_hypotheses",
    "heading_allowance",
    "in_plain_sight",
    "radio_contradiction",
    "window",
]


class TeamCoordinator:
    """Drives a team of N robots through the four kinds of interaction (module notes).

    Parameters
    ----------
    config : TeamConfig
        Defaults to the default env's robots and sensors; :meth:`for_env` follows a given
        env's.
    rng : numpy.random.Generator
        All randomness (policies' and explorers' tie-breaking, merging).
    n_robots : int
        Team size (>= 2; the env's ``n_robots``).
    policy_factory : PolicyFactory, optional
        Builds each robot's exploration policy (``factory(env, rng)``, the robot's own
        generator drawn from ``rng``); None: the frontier explorer with ``config.explorer``.
    env : EnvConfig, optional
        What ``policy_factory`` is given (default: the default env).

    Attributes
    ----------
    policies : list of ExplorationPolicy
        Each robot's policy.
    explorers : list of ExplorerPolicy
        What drives each robot's legs to a given goal: the policy itself when it is a
        frontier explorer, else one of the team's own.
    roots : list of int
        Per robot, the lowest robot of its group (the robots its verified transforms
        connect it to); the common frame is the group of robot 0.
    frames : list of ndarray (3,)
        Per robot, ``root_from_map``: its map frame in its group root's map frame (robot
        0's, the common frame, once it joined).
    pair : tuple of int
        The two robots whose groups are being merged (side 0, side 1; the lower root
        first), or were last.
    contact, proposals, verification, groups, allocation
        The roles (module notes): :class:`~agents.team_contact.Contact`,
        :class:`~agents.team_proposals.Proposals`,
        :class:`~agents.team_verification.Verification`,
        :class:`~agents.team_groups.Groups`, :class:`~agents.team_allocation.Allocation`.

    Use: each step call :meth:`act` with the env observations and a function giving robot
    i's current own map; read :attr:`state`, :meth:`common_transform`, :attr:`merged_map`,
    :attr:`rendezvous_point`, :meth:`plan_of` and :meth:`frontiers_of` for recording;
    :meth:`pop_decisions` returns what was decided since the last call.
    """

    def __init__(
        self,
        config: TeamConfig | None = None,
        *,
        rng: np.random.Generator,
        n_robots: int = 2,
        policy_factory: PolicyFactory | None = None,
        env: EnvConfig | None = None,
    ) -> None:
        if not isinstance(n_robots, int) or isinstance(n_robots, bool) or n_robots < 2:
            raise ValueError(f"a team needs n_robots >= 2, got {n_robots!r}")
        self.config = config if config is not None else TeamConfig()
        self.rng = rng
        # Sighting hypotheses are refined with a generator of their own, so that one formed
        # (and perhaps set aside) does not shift the draws of the merges and explorers.
        sighting_rng = rng.spawn(1)[0]
        self.n_robots = n_robots
        self.policies: list[ExplorationPolicy] = []
        self.explorers: list[ExplorerPolicy] = []
        for _ in range(n_robots):
            seed = rng.integers(2**63)
            policy: ExplorationPolicy
            if policy_factory is None:
                explorer = ExplorerPolicy(np.random.default_rng(seed), self.config.explorer)
                policy = explorer
            else:
                env_config = env if env is not None else DEFAULT_ENV
                policy = build_policy(policy_factory, env_config, np.random.default_rng(seed))
                if isinstance(policy, ExplorerPolicy):
                    explorer = policy
                else:  # the team's own explorer drives the legs to a given goal
                    goal_rng = np.random.default_rng([int(seed), 1])
                    explorer = ExplorerPolicy(goal_rng, self.config.explorer)
            self.policies.append(policy)
            self.explorers.append(explorer)
        n = n_robots
        self.state = TeamState.NO_INTERACTION
        self.step = 0
        # --- the group structure (written by ``groups`` only) ---
        self.roots = list(range(n))
        self.frames: list[FloatArray] = [np.zeros(3) for _ in range(n)]
        self.verified: list[FloatArray | None] = [None] * n
        """Per robot, ``common_from_map`` as verified (the hypotheses before refinement,
        composed), once it joined the common frame; None before."""
        self.step_joined: list[int | None] = [0] + [None] * (n - 1)
        self.views: list[GridMap | None] = [None] * n
        """Per robot in the common frame, the merged map it explores, in robot 0's frame:
        its own map, current, fused with the others' as it last received them. One map
        while every link among them is up; while one is down, each robot still sees all
        of its own mapping (a robot exploring on a stale copy of its own map drives to
        frontiers it has already explored)."""
        # --- the state's data: the pair being merged, its hypotheses, the one under test ---
        self.pair: tuple[int, int] = (0, 1)
        self.hypotheses: list[FloatArray] = []
        """The current pair's hypotheses (``side0_from_side1``: group frame from group
        frame), best first."""
        self.hypothesis_sources: list[str] = []
        """Per entry of :attr:`hypotheses`, where it came from (:class:`Acceptance`'s
        ``proposed_by``); for the recording only."""
        self.hypotheses_attempt: int | None = None
        """The merge attempt that gave :attr:`hypotheses` (None: from sightings)."""
        self.rendezvous: _Rendezvous | None = None
        self._rejected: dict[tuple[int, int], list[FloatArray]] = {}
        """Per pair of group roots, the hypotheses a rendezvous rejected: the maps' frames
        never move, so they stay wrong and are not tried again."""
        # --- the report's tallies (the roles add to them) ---
        self.hypotheses_tested = 0
        self.rendezvous_steps = 0
        """Robot-steps spent driving to a meeting point or waiting there."""
        self.first_hypothesis_step: int | None = None
        """The step the first hypothesis was put to verification (any kind)."""
        self.first_rendezvous_step: int | None = None
        """The step robots were first driven to a meeting point."""
        self.seeking_steps = [0] * n
        """Per robot, the steps it spent seeking contact (driving back and waiting)."""
        self.sighting_hypotheses = 0
        """Hypotheses formed from sightings (:attr:`TeamConfig.sighting_count`)."""
        self.radio_rejections = 0
        """Hypotheses rejected by the radio (:attr:`TeamConfig.radio_margin`)."""
        self.acceptances: list[Acceptance] = []
        """Every hypothesis accepted, in order; for the recording only."""
        self._decisions: list[Decision] = []
        # --- the step snapshot ---
        self._poses = [np.zeros(3) for _ in range(n)]
        self._last_poses = [np.zeros(3), np.zeros(3)]
        """The current pair's poses, each in its group root's frame."""
        self._last_observations: list[dict[str, Any]] = []
        """The current pair's observations, as two robots see each other (``peer`` and
        ``comm`` of the partner only)."""
        self._links = np.zeros((n, n), dtype=bool)
        self._reach = np.eye(n, dtype=bool)
        self._link = False
        """The current pair's link."""
        self._maps: MapSource = _no_map
        """The robots' own maps (the last ``maps`` given to :meth:`act`)."""
        self._on_goal = [False] * n
        """Per robot, whether the team drives it to a given goal (else its policy acts)."""
        # --- the roles ---
        self.contact = Contact(self)
        self.proposals = Proposals(self, sighting_rng=sighting_rng)
        self.verification = Verification(self)
        self.groups = Groups(self)
        self.allocation = Allocation(self)

    @classmethod
    def for_env(
        cls,
        env: EnvConfig,
        *,
        rng: np.random.Generator,
        config: TeamConfig | None = None,
        n_robots: int = 2,
        policy_factory: PolicyFactory | None = None,
    ) -> TeamCoordinator:
        """A team for the env's robots and sensors: ``config`` (checked against the env)
        or :meth:`TeamConfig.for_env`; ``policy_factory`` builds the policies for ``env``."""
        if config is None:
            config = TeamConfig.for_env(env)
        config.check_env(env)
        return cls(config, rng=rng, n_robots=n_robots, policy_factory=policy_factory, env=env)

    # --- what recording reads -----------------------------------------------------------

    @property
    def members(self) -> list[int]:
        """The robots in the common frame (robot 0's group), in index order."""
        return [i for i in range(self.n_robots) if self.roots[i] == 0]

    def common_transform(self, robot: int) -> FloatArray | None:
        """``map0_from_map<robot>`` once ``robot`` joined the common frame, else None."""
        return self.frames[robot].copy() if self.roots[robot] == 0 else None

    @property
    def transform(self) -> FloatArray | None:
        """``map0_from_map1`` once robot 1 joined (refined), else None (two robots)."""
        return None if self.step_joined[1] is None else self.frames[1]

    @property
    def preliminary_transform(self) -> FloatArray | None:
        """Robot 1's ``map0_from_map1`` as verified, before refinement, or None."""
        return self.verified[1]

    @property
    def step_verified(self) -> int | None:
        """The step of the first verified merge, or None."""
        steps = [s for s in self.step_joined[1:] if s is not None]
        return min(steps) if steps else None

    @property
    def rejected(self) -> list[FloatArray]:
        """The current pair's rejected hypotheses."""
        return self._rejected.setdefault(self._pair_roots(), [])

    @property
    def merged_map(self) -> GridMap | None:
        """Robot 0's view of the merged map (its own map and the others' as last
        received), in map 0's frame, or None before a merge; robot i explores
        :attr:`views` ``[i]``."""
        return self.views[0]

    @property
    def rendezvous_point(self) -> FloatArray | None:
        """The meeting point in the frame of side 0's group root while verifying."""
        return None if self.rendezvous is None else self.rendezvous.meeting_point.copy()

    def plan_of(self, robot: int) -> FloatArray:
        """The path ``robot`` follows, (P, 2) in the frame of the map it explores: the
        team's on a leg to a given goal, else its policy's ``plan`` (empty if it has none)."""
        source: Any = self.explorers[robot] if self._on_goal[robot] else self.policies[robot]
        return as_points(getattr(source, "plan", None))

    def frontiers_of(self, robot: int) -> FloatArray:
        """The frontiers ``robot``'s policy found (its ``frontiers``, (F, 2)), or empty."""
        return as_points(getattr(self.policies[robot], "frontiers", None))

    def done(self, robot: int) -> bool:
        """Whether ``robot``'s policy reports that nothing is left to explore (its
        ``done``; a policy without one never is)."""
        return bool(getattr(self.policies[robot], "done", False))

    def coordinated(self, robot: int) -> bool:
        """Whether ``robot`` explores the merged map in the common frame."""
        return self.roots[robot] == 0 and self.views[robot] is not None

    def explored_frame(self, robot: int) -> FloatArray | None:
        """``root_from_explored``: from the frame of the map ``robot`` explores (the
        common frame while coordinated, else its own) to its group root's frame; None
        when they are one frame."""
        if self.coordinated(robot) or self.roots[robot] == robot:
            return None
        return self.frames[robot]

    def pose_in_root(self, robot: int, pose: ArrayLike) -> FloatArray:
        """``robot``'s SLAM ``pose`` (own map frame) in its group root's frame."""
        pose = np.asarray(pose, dtype=np.float64)
        return pose if self.roots[robot] == robot else compose(self.frames[robot], pose)

    @property
    def merge_pending(self) -> bool:
        """Whether a merge is under way or may come soon without the maps growing: maps
        being merged, a hypothesis under verification, sightings being gathered into
        one, or a robot seeking contact (``mrslam run``'s ``until_merged`` waits on it)."""
        if self.state in (TeamState.HYPOTHESIS_GENERATION, TeamState.HYPOTHESIS_VERIFICATION):
            return True
        return self.proposals.is_gathering() or self.contact.is_seeking()

    def source_of(self, rendezvous: _Rendezvous) -> str:
        """Where the hypothesis of ``rendezvous`` came from (:class:`Acceptance`'s
        ``proposed_by``)."""
        if rendezvous.formed_at is not None:
            return "sighting"
        sources = self.hypothesis_sources
        return sources[rendezvous.index] if rendezvous.index < len(sources) else "virtual robot"

    def pop_decisions(self) -> list[Decision]:
        decisions, self._decisions = self._decisions, []
        return decisions

    def pop_merge_attempts(self) -> list[MergeAttempt]:
        """The merge attempts since the last call (empty unless ``config.keep_merges``)."""
        return self.proposals.pop_merge_attempts()

    def _decide(self, text: str) -> None:
        self._decisions.append(Decision(self.step, text))

    def _note_hypothesis(self) -> None:
        if self.first_hypothesis_step is None:
            self.first_hypothesis_step = self.step

    # --- the step -----------------------------------------------------------------------

    def act(self, observations: list[dict[str, Any]], maps: MapSource) -> list[NDArray[np.float32]]:
        """Actions for all robots (normalised ``(v, omega)``).

        Parameters
        ----------
        observations : list of dict
            The env observations of robot 0, 1, ... (``pose``, ``scan``, ``peer``,
            ``comm``).
        maps : callable
            ``maps(i)`` is robot i's current own map (called only when needed).
        """
        self.step += 1
        n = self.n_robots
        self._maps = maps
        self._poses = [np.asarray(o["pose"], dtype=np.float64) for o in observations]
        links = links_of(observations, n)
        self._links, self._reach = links, _reachable(links)
        self.contact.record(self._poses, links)
        self._observe_pair(observations)
        if self.config.interaction:
            self.contact.seek()
            # Outside a merge: a chance meeting's sightings first, else a merge of maps.
            if self.state in (
                TeamState.NO_INTERACTION,
                TeamState.COORDINATED_EXPLORATION,
            ) and not self.proposals.maybe_sighting(observations, maps):
                self.proposals.maybe_generate(observations, maps)
            elif self.proposals.waiting_on_sightings():
                # A hypothesis waits for a chance meeting (one just formed from sightings
                # too): the maps are merged again beside it as they grow.
                self.proposals.generate_beside_sightings(maps)
            if self.state is TeamState.HYPOTHESIS_VERIFICATION:
                sides = self._side_maps(maps)
                self.verification.verify(self._last_observations, sides, self._link)
            rendezvous = self.rendezvous
            if rendezvous is not None and not rendezvous.in_place:
                self.rendezvous_steps += sum(self._on_goal[r] for r in self.pair)
            if len(self.members) > 1:
                self.groups.keep_merged_map(maps)
        if len(self.members) > 1 and self.merged_map is not None:
            return self.allocation.act(observations, maps)
        return [self.act_alone(i, observations[i], maps(i)) for i in range(n)]

    def act_alone(
        self, robot: int, observation: dict[str, Any], own_map: GridMap
    ) -> NDArray[np.float32]:
        """``robot``'s action on its own map, in its own frame, knowing no teammate (the
        team's step outside the common frame; the one-robot baseline calls it directly)."""
        if self._on_goal[robot]:
            return self.explorers[robot].act(observation, own_map)
        pose = np.asarray(observation["pose"], dtype=np.float64)
        context = PolicyContext(
            robot=robot, step=self.step, map=own_map, pose=pose, own_map=own_map
        )
        return self.policies[robot].act(observation, context)

    def start_coordinated(self, transform: ArrayLike, maps: MapSource) -> None:
        """Skip merging and verification: coordinate from now on with known transforms
        (the benchmark's oracle, given the true relative poses): ``map0_from_map1`` (3,),
        or with more robots (N-1, 3), ``map0_from_map_i`` for i = 1 ... N-1.

        What follows is the coordination that follows a verified merge; the robots'
        current maps count as exchanged (at the start, one scan each). A team made
        without interaction (robots exploring independently so far: the benchmark's late
        oracle) interacts from now on.
        """
        transforms = np.asarray(transform, dtype=np.float64).reshape(-1, 3)
        if len(transforms) != self.n_robots - 1:
            raise ValueError(
                f"start_coordinated needs {self.n_robots - 1} transforms, got {len(transforms)}"
            )
        self._maps = maps
        if not self.config.interaction:
            self.config = replace(self.config, interaction=True)
        self._decide("relative pose given (oracle): coordinated exploration on the merged map")
        for robot in range(self.n_robots):
            self._release(robot)
        self.groups.give(transforms)
        self._rest()
        self.groups.exchange_and_fuse(everyone=True)

    # --- the transitions: every change of ``state`` ---------------------------------------

    def _generating(self) -> None:
        """-> ``hypothesis_generation``: the current pair's maps are being merged (left
        within the same step, for verification or rest)."""
        self.state = TeamState.HYPOTHESIS_GENERATION

    def _verifying(self, rendezvous: _Rendezvous) -> None:
        """-> ``hypothesis_verification``: ``rendezvous`` is the hypothesis under test."""
        self.rendezvous = rendezvous
        self.state = TeamState.HYPOTHESIS_VERIFICATION

    def _accepted(self) -> None:
        """``hypothesis_verification`` -> rest, once the accepted hypothesis joined the
        pair's groups (:meth:`~agents.team_groups.Groups.join_pair`): coordinated exploration
        if robot 0's group has a teammate (its robots' views are made now)."""
        self._rest()
        if len(self.members) > 1:
            # Only a join into the common frame makes merged views; a view made for
            # robot 0 alone would be a frozen copy of its map, which its later merges with
            # other groups would then use instead of its current map.
            self.groups.exchange_and_fuse(everyone=False)

    def _rest(self) -> None:
        """No merge under way: coordinated if robot 0 has a teammate in its frame."""
        self.hypotheses = []
        self.hypothesis_sources = []
        self.rendezvous = None
        coordinated = len(self.members) > 1
        self.state = TeamState.COORDINATED_EXPLORATION if coordinated else TeamState.NO_INTERACTION

    # --- the pair being merged, and the legs the team drives ------------------------------

    def _pair_roots(self) -> tuple[int, int]:
        return self.roots[self.pair[0]], self.roots[self.pair[1]]

    def _set_pair(self, a: int, b: int) -> None:
        """Merge the groups of robots ``a`` and ``b`` next: side 0 is the lower root's."""
        self.pair = (a, b) if self.roots[a] < self.roots[b] else (b, a)

    def _observe_pair(self, observations: list[dict[str, Any]]) -> None:
        """The current pair as two robots: poses in their group roots' frames, each one's
        peer row and link of the other."""
        a, b = self.pair
        pair_view = []
        for me, other in ((a, b), (b, a)):
            observation = observations[me]
            row = _row(me, other)
            pose = self.pose_in_root(me, self._poses[me])
            pair_view.append(
                {
                    **observation,
                    "pose": pose,
                    "peer": np.asarray(observation["peer"])[row : row + 1],
                    "comm": np.asarray(observation["comm"])[row : row + 1],
                }
            )
        self._last_observations = pair_view
        self._last_poses = [o["pose"] for o in pair_view]
        self._link = bool(self._links[a, b])

    def _side_maps(self, maps: MapSource) -> MapSource:
        """``sides(k)``: the map of the current pair's side k (its group's, in its root's
        frame)."""
        cache: dict[int, GridMap] = {}

        def sides(k: int) -> GridMap:
            if k not in cache:
                cache[k] = self.groups.group_map(self.pair[k], maps)
            return cache[k]

        return sides

    def _send(self, side: int, goal: FloatArray) -> None:
        """Drive the pair's side-``side`` robot to ``goal`` (its group root's frame) with
        the team's explorer, in the frame of the map it explores."""
        robot = self.pair[side]
        if not self.coordinated(robot) and self.roots[robot] != robot:
            goal = transform_points(inverse(self.frames[robot]), goal[None, :2])[0]
        self.explorers[robot].set_goal(goal)
        self._on_goal[robot] = True

    def _release(self, robot: int) -> None:
        """End ``robot``'s leg to a given goal: its policy explores again."""
        self.explorers[robot].clear_goal()
        self._on_goal[robot] = False

    def _release_pair(self) -> None:
        for robot in self.pair:
            self._release(robot)

    def _change_frame(self, robot: int, new_from_old: FloatArray) -> None:
        """``robot`` now explores in another frame: its policy (when it can) and the
        team's explorer carry what they remember over."""
        change = getattr(self.policies[robot], "change_frame", None)
        if change is not None:
            change(new_from_old)
        if self.explorers[robot] is not self.policies[robot]:
            self.explorers[robot].change_frame(new_from_old)


def _no_map(robot: int) -> GridMap:
    raise RuntimeError("the team has not acted yet: no maps")
