"""One scan's competing answers against one map: each start polished once and measured (:mod:`.answer`).

A start is polished finely, or *wide* (:mod:`.polish`: GICP against the map's last scan, then fine): a wide
polish whose basin stage lands on an answer already there is not polished again; the kinds of start that reached
an answer are its *support* (the prediction among them: the prediction's basin holds it). An answer that would
stand is *reviewed*: polished wide from its own pose, where the map's last scan alone leads from it (rule 7 of
:mod:`.decision`). The contest also keeps the
prediction the answers are judged near (recentred when the prediction left the map and the global search ran
around where the map last grew instead), why a start found no map to register against, and which kinds of
independent start have competed (:class:`~.evidence.Evidence`), and measures on demand how much of the scan an
answer puts where the map's last scan saw empty space (:mod:`~cemnet_ros.pipeline.map.free_space`; on
``FREE_SPACE_POINTS`` of the polish points: the share, not every point, is the evidence).
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from cemnet_ros.core.geometry import apply_transform
from cemnet_ros.pipeline.config import HealthConfig
from cemnet_ros.pipeline.steps.answer import Answer, Origin, distinct, measured
from cemnet_ros.pipeline.steps.evidence import Evidence, Expectation
from cemnet_ros.pipeline.steps.health import Level
from cemnet_ros.pipeline.steps.polish import Polisher

FREE_SPACE_POINTS = 1000


class Contest:
    """The answers of one scan (:attr:`answers`), polished from the starts entered, around ``T_predicted``."""

    def __init__(self, polisher: Polisher, T_predicted: np.ndarray) -> None:
        self.polisher, self.T_predicted = polisher, T_predicted
        self.answers: list[Answer] = []
        self._entered: list[tuple[np.ndarray, bool]] = []  # (start, wide) already polished
        self._arrivals: list[tuple[Origin, np.ndarray]] = []  # every start's landing place, polished or not
        self._reviewed: list[np.ndarray] = []  # the poses of the answers reviewed from the map's last scan
        self.polishes = 0  # fine polishes run (the contest's cost, reported per scan)
        self.searched = False  # the global search's hypotheses have competed
        self.neighbours_checked = False  # the leader's rotational neighbours have competed
        self.missing = ""  # why a start had no map to register against (the step's reason when none had)
        self._seen_through: dict[int, float] = {}

    def enter(self, T_start: np.ndarray, origin: Origin, *, wide: bool = False, spread_m: float = 0.0
              ) -> Optional[Answer]:
        """Polish ``T_start`` (wide: the basin first) and measure it; the answer, or None when this start was
        entered already or its basin is an answer already there. ``spread_m``: the CEM's final spread."""
        if any(w == wide and not distinct(T_start, T) for T, w in self._entered):
            return None
        self._entered.append((T_start, wide))
        return self._polished(T_start, origin, wide, spread_m)

    def review(self, answer: Answer) -> Optional[Answer]:
        """Polish ``answer`` wide from its own pose (:mod:`.polish`: GICP against the map's last scan, then fine):
        the new answer where the last scan leads to a distinct one, else None (the answer's support grows; a
        polish that lands within the node's precision of an answer enters nothing: a review that agrees changes
        nothing)."""
        self._reviewed.append(answer.T_odom_sensor)
        return self._polished(answer.T_odom_sensor, Origin.LAST_SCAN, wide=True, distinct_only=True)

    def _polished(self, T_start: np.ndarray, origin: Origin, wide: bool, spread_m: float = 0.0,
                  distinct_only: bool = False) -> Optional[Answer]:
        """The answer polished from ``T_start``, or None where its basin is an answer already there
        (``distinct_only``: or where the polish lands within the node's precision of one)."""
        T_polish_start = T_start
        if wide:
            T_polish_start = self.polisher.basin(T_start)
            if any(not distinct(T_polish_start, a.T_odom_sensor) for a in self.answers):
                self._arrivals.append((origin, T_polish_start))
                return None
        polish = self.polisher.fine(T_polish_start)
        self.polishes += 1
        if distinct_only and any(not distinct(polish.T_target_source, a.T_odom_sensor) for a in self.answers):
            self._arrivals.append((origin, polish.T_target_source))
            return None
        answer = measured(self.polisher, T_start, polish, origin, self.T_predicted, spread_m)
        self.answers.append(answer)
        self._arrivals.append((origin, answer.T_odom_sensor))
        return answer

    def reviewed(self, answer: Answer) -> bool:
        """:meth:`review` ran on ``answer``: the map's last scan alone has had its say on it."""
        return any(T is answer.T_odom_sensor for T in self._reviewed)

    def support(self, answer: Answer) -> frozenset[Origin]:
        """The kinds of start that reached ``answer``."""
        return frozenset(origin for origin, T in self._arrivals if not distinct(T, answer.T_odom_sensor))

    def seen_through(self, answer: Answer) -> float:
        """The share of the scan ``answer`` puts in the free space of the map's last scan (0 without one)."""
        if id(answer) not in self._seen_through:
            free_space = self.polisher.map.free_space
            points = self.polisher.frame.polish[:FREE_SPACE_POINTS]
            self._seen_through[id(answer)] = 0.0 if free_space is None else free_space.seen_through(
                apply_transform(answer.T_odom_sensor, points))
        return self._seen_through[id(answer)]

    def recentre(self, T_guess: np.ndarray) -> None:
        """Judge the answers around ``T_guess`` instead of the prediction (which left the map; only before any
        answer was entered, so that every answer is judged against the same guess)."""
        assert not self.answers, "the answers were judged against the prediction"
        self.T_predicted = T_guess

    def evidence(self, near: tuple[float, float], level: Optional[Level], rules: HealthConfig,
                 search_because: str = "", moving: bool = True) -> Evidence:
        """The record the decision reads (:class:`~.evidence.Evidence`)."""
        expectation = Expectation(self.T_predicted, near, level, search_because, moving, self.polisher.reach)
        return Evidence.of(self.answers, expectation, rules, support=self.support, seen_through=self.seen_through,
                           searched=self.searched, neighbours_checked=self.neighbours_checked,
                           last_scan_checked=self.reviewed, missing=self.missing)
