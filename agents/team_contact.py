"""The team's contact role: who can talk to whom, the link history, contact seeking.

A role of :class:`agents.team.TeamCoordinator` (design §6). Each step the coordinator
reads the links from the observations (:func:`links_of`, :func:`reachable`), hands them to
:meth:`Contact.record` and runs :meth:`Contact.seek`.

Interface
---------
:func:`links_of`, :func:`reachable`, :func:`peer_row`
    The links between the robots (both ends must hear each other), who can exchange data
    through teammates, and a robot's row in another's ``peer`` and ``comm`` observations.
:meth:`Contact.record`
    The link history: every robot's position (own map frame) and the links, on every
    step; the radio checks of the verification role (:mod:`agents.team_verification`)
    judge a hypothesis on it (:attr:`Contact.tracks`, :attr:`Contact.link_track`).
:meth:`Contact.seek`
    The contact-seeking rule (:attr:`agents.team_config.TeamConfig.seek_contact_after`):
    a robot that lost its link to the robots outside its group drives back to where it
    had it and waits there; :attr:`Contact.seeking` holds who seeks, since when.
:meth:`Contact.is_seeking`
    Whether any robot seeks contact (:attr:`TeamCoordinator.merge_pending`).

State it owns: the link history, and per robot the last link's step and places, the
search under way and when the next may start. It reads the coordinator's step snapshot
(step, poses, links, groups) and drives a robot's legs through the coordinator's
explorers; the robot-steps spent seeking go to :attr:`TeamCoordinator.seeking_steps`.
"""

from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from agents.team_config import FloatArray
from mrslam_env.geometry import transform_points

if TYPE_CHECKING:
    from agents.team import TeamCoordinator

__all__ = ["Contact", "links_of", "peer_row", "reachable"]


class Contact:
    """Contact seeking and the link history of ``team``'s robots (module notes)."""

    def __init__(self, team: TeamCoordinator) -> None:
        self.team = team
        n = team.n_robots
        self._contact_step: list[int | None] = [None] * n
        """Per robot, the last step it had a link to a robot outside its group (None:
        never)."""
        self._contact_track: list[deque[FloatArray]] = [
            deque(maxlen=team.config.seek_contact_back + 1) for _ in range(n)
        ]
        """Per robot, where it was (own map frame) on the last steps of its last link,
        at most ``seek_contact_back + 1`` of them: the first is the place it seeks."""
        self._seek_from = [0] * n
        """Per robot, the step its time without a link counts from for the next search
        (the end of the last one)."""
        self.seeking: list[tuple[int, int | None] | None] = [None] * n
        """Per robot seeking contact: the step it began and the step it arrived at the
        place (None while on its way); None when not seeking."""
        self.tracks: list[list[FloatArray]] = [[] for _ in range(n)]
        """Per robot, its position (own map frame) on every step so far."""
        self.link_track: list[NDArray[np.bool_]] = []
        """The links between the robots (n, n) on every step so far."""

    def record(self, poses: list[FloatArray], links: NDArray[np.bool_]) -> None:
        """The step's positions and links into the link history (kept while the team
        interacts and the radio checks use it: ``radio_margin`` not None)."""
        config = self.team.config
        if config.interaction and config.radio_margin is not None:
            for i in range(self.team.n_robots):
                self.tracks[i].append(poses[i][:2].copy())
            self.link_track.append(links)

    def is_seeking(self) -> bool:
        """Whether a robot seeks contact."""
        return any(seeking is not None for seeking in self.seeking)

    def seek(self) -> None:
        """The contact-seeking rule (:attr:`TeamConfig.seek_contact_after`): a robot that
        lost its link to the robots outside its group goes back to where it was
        ``seek_contact_back`` steps before it lost it and waits there; any such link ends
        the seeking."""
        team = self.team
        config = team.config
        after = config.seek_contact_after
        if not after:  # switched off
            return
        for i in range(team.n_robots):
            outside = [j for j in range(team.n_robots) if team.roots[j] != team.roots[i]]
            if any(team._links[i, j] for j in outside):
                if self._contact_step[i] != team.step - 1:
                    self._contact_track[i].clear()  # a new link: where it came up first
                self._contact_step[i] = team.step
                self._contact_track[i].append(team._poses[i][:2].copy())
                if self.seeking[i] is not None:
                    self._stop(i, f"link up again after {team.seeking_steps[i]} steps")
                continue
            seeking = self.seeking[i]
            if seeking is not None:
                team.seeking_steps[i] += 1
                started, arrived = seeking
                if arrived is None:
                    status = team.explorers[i].status
                    if status == "arrived":
                        self.seeking[i] = (started, team.step)
                    elif status == "goal_unreachable":
                        self._stop(i, "the place is out of reach on its map")
                    elif team.step - started >= after:
                        self._stop(i, f"not back at the place in {after} steps")
                # The partner, gone as long, may take up to ``after`` steps to come back.
                elif team.step >= max(arrived + config.seek_contact_wait, started + after):
                    self._stop(i, "no link at the place of the last one")
                continue
            last = self._contact_step[i]
            if not outside or last is None or team._on_goal[i]:
                continue
            if team.step - max(last, self._seek_from[i]) < after:
                continue
            place = self._contact_track[i][0]
            goal = transform_points(team.frames[i], place[None, :])[0]
            team.explorers[i].set_goal(goal if team.coordinated(i) else place)
            team._on_goal[i] = True
            self.seeking[i] = (team.step, None)
            back = len(self._contact_track[i]) - 1
            team._decide(
                f"robot_{i}: no link for {team.step - last} steps; back to where it was "
                f"{back} steps before losing it ({place[0]:.1f}, {place[1]:.1f} in its map) "
                "to seek contact"
            )

    def _stop(self, robot: int, why: str) -> None:
        team = self.team
        self.seeking[robot] = None
        team._release(robot)
        self._seek_from[robot] = team.step  # the next search a full interval from now
        team._decide(f"robot_{robot}: contact seeking ends ({why})")


def links_of(observations: list[dict[str, Any]], n: int) -> NDArray[np.bool_]:
    """The links between ``n`` robots, (n, n) bool: up when both ends hear each other
    (their ``comm`` observations)."""
    links = np.zeros((n, n), dtype=bool)
    for i in range(n):
        for j in range(i + 1, n):
            up = bool(observations[i]["comm"][peer_row(i, j)])
            up = up and bool(observations[j]["comm"][peer_row(j, i)])
            links[i, j] = links[j, i] = up
    return links


def peer_row(robot: int, other: int) -> int:
    """The row of ``other`` in ``robot``'s ``peer`` and ``comm`` observations (index
    order, itself skipped)."""
    return other if other < robot else other - 1


def reachable(links: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """Which robots can exchange data, directly or through teammates (the transitive
    closure of ``links``, (N, N) bool; each robot reaches itself)."""
    reach = links | np.eye(len(links), dtype=bool)
    for k in range(len(links)):
        reach = reach | (reach[:, k : k + 1] & reach[k : k + 1, :])
    return reach
