"""The decision: can the node vouch for this scan's leading answer? One function over one record of evidence.

The rules, in the order :func:`decide` applies them (the first that applies decides; the thresholds are
``health.*`` parameters, docs/node.md says what each one's figures were measured on). Answers that contradict what
the map's last scan saw empty have not competed (:mod:`.evidence`).

1. **No answer, or no overlap**: no map near the guess, too few point-to-plane pairs, a fitness below
   ``min_fitness`` or below ``fitness_drop`` x the running level: *failed* (the prediction is published).
2. **The search must compete first** where the caller says so (the first pair, after a failed step, on request).
3. **Near-tie**: distinct answers within ``tie_ratio`` in consistency. The global search competes first; then the
   one next to the prediction is kept as a *near-tie* (flagged, the map does not take it in), and with none next
   to it the step is *ambiguous* (failed).
4. **Confirmed where expected**: the leader fits and covers the map at ``confirm_ratio`` x the running levels of the
   vouched steps (a wrong turn in a building fits the walls as well as the truth, but leaves part of the scan where
   the map has nothing) and the prediction expects it (:attr:`~.evidence.Evidence.expected`: the prediction's polish
   reached it or it lies within the prediction's spread): it stands without further starts. Anything else waits for
   the global search, whose starts are independent of the prediction; after it an answer stands when it is confirmed,
   or when the prediction expects it and it still overlaps (rule 1). Without a running level (a first pair; a map
   restarted after a lost stretch) nothing is confirmed: the answer stands when the prediction expects it, or, where
   no motion is known yet (a first pair), when the search found no near-tie and no more consistent answer that the
   map's last scan saw through (the survivor of such a veto is no evidence on its own: a car's scan 36 m back along
   a road); and then at least as much of the scan must lie on the map's surfaces as off the map (consistency >= 0).
   Where a live scan's budget leaves no time for the search, the registration turns a verdict still waiting for it
   into *unconfirmed*, or *ambiguous* for equals none next to the prediction (:mod:`.registration`,
   :mod:`.scan_budget`).
5. **Displaced**: an answer that stands on that evidence but lies farther from the predicted position than the
   fine polish reaches (along a known motion) waits for its neighbours: its own rotation at the predicted
   position competes. A slide along a weakly constrained direction keeps the right rotation (3-5 m on Livox
   keyframes, with the right turn); a right answer that far off a poor prediction still leads.
6. **Weak view**: an answer whose conditioning is below ``neighbour_conditioning`` (a narrow field of view down a
   flat valley) but not degenerate waits for its rotational neighbours to compete (a near-tie then flags it,
   rule 3).
7. **Seen from the last scan**: an answer that stands on that evidence, unless the prediction's own fine polish
   converged to it (*explained*: a steady motion), waits for its own wide polish (GICP against the map's last
   scan from it, then fine). Where the map has grown from a slid or turned step, its older parts can outvote the
   scan it took in last; from there the polish lands on an answer of its own, which competes (a near-tie, rule 3;
   a clearly more consistent one leads and is judged in turn).
8. **Degenerate**: an answer whose view leaves a direction weakly constrained (conditioning below
   ``min_conditioning``): flagged; its pose is the answer as registered (where the scan's weak pull leaves it: on
   the corpus nearer the truth along that direction than the prediction on 9 degenerate steps in 10, on keyframes
   and on a 10 Hz handheld alike), its covariance the prediction's along that direction; the map takes it in.
9. **Disputed by the last scan**: an answer whose own review (rule 7) lands on a distinct answer: the map and the
   scan it took in last disagree on it, and the step is judged from that scan. The global search competes first;
   then the leader is kept as a *near-tie* (flagged, the map does not take it in). Not without a running level
   (a first pair, a map just restarted): that map is its last scan, and a disagreement there is only GICP's and
   the point-to-plane polish's on the same scan.
10. Otherwise: *accepted*.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from cemnet_ros.pipeline.config import HealthConfig
from cemnet_ros.pipeline.steps.answer import Answer
from cemnet_ros.pipeline.steps.evidence import Evidence
from cemnet_ros.pipeline.steps.health import Level


class Outcome(str, enum.Enum):
    """What a scan's registration comes to."""

    ACCEPTED = "accepted"  # vouched for: the pose, the map, the motion model and the level take it in
    DEGENERATE = "degenerate"  # flagged: a direction weakly constrained; the map takes it in
    NEAR_TIE = "near-tie"  # flagged: equals, or the map and its last scan disagree; the pose and the level move
    UNCONFIRMED = "unconfirmed"  # flagged: the search it waited for did not fit a live scan's budget; as a near-tie
    AMBIGUOUS = "ambiguous"  # failed: equals, none next to the prediction
    FAILED = "failed"  # the prediction is published, flagged
    UNSETTLED = "unsettled"  # more starts must compete first (``Verdict.needs``)


class Needs(str, enum.Enum):
    """The starts an unsettled verdict waits for."""

    SEARCH = "search"
    NEIGHBOURS = "neighbours"
    LAST_SCAN = "last scan"


@dataclass(frozen=True)
class Verdict:
    """An outcome and why (empty for an accepted step); ``needs``: the starts an unsettled one waits for."""

    outcome: Outcome
    reason: str = ""
    needs: Needs | None = None

    @property
    def vouched(self) -> bool:
        return self.outcome == Outcome.ACCEPTED

    @property
    def failed(self) -> bool:
        """The answer is not published: the prediction is, flagged."""
        return self.outcome in (Outcome.FAILED, Outcome.AMBIGUOUS, Outcome.UNSETTLED)


def weak_view(answer: Answer, rules: HealthConfig) -> bool:
    """``answer``'s view is weakly constrained (rule 6): its rotational neighbours compete before it stands."""
    return answer.signals.conditioning < rules.neighbour_conditioning


def shortfall(answer: Answer, level: Level, rules: HealthConfig) -> str:
    """Where ``answer`` fits or covers less than ``confirm_ratio`` x the running level (rule 4; "": it does
    neither)."""
    if answer.fitness < rules.confirm_ratio * level.fitness:
        return f"fitness {answer.fitness:.3f} < {rules.confirm_ratio:.2f} x its running level {level.fitness:.3f}"
    if answer.coverage < rules.confirm_ratio * level.coverage:
        return f"coverage {answer.coverage:.3f} < {rules.confirm_ratio:.2f} x its running level {level.coverage:.3f}"
    return ""


def decide(evidence: Evidence, rules: HealthConfig) -> Verdict:
    """The verdict on ``evidence`` (see the module for the rules)."""
    leader, expected = evidence.leader, evidence.expectation
    if leader is None:
        return Verdict(Outcome.FAILED, evidence.missing)
    level = expected.level
    if not leader.constrained:
        return Verdict(Outcome.FAILED, f"only {leader.n_pairs} point-to-plane pairs")
    if leader.fitness < rules.min_fitness:
        return Verdict(Outcome.FAILED, f"low fitness {leader.fitness:.3f} < {rules.min_fitness:.3f}")
    if level is not None and leader.fitness < rules.fitness_drop * level.fitness:
        return Verdict(Outcome.FAILED, f"fitness {leader.fitness:.3f} fell below {rules.fitness_drop:.2f} x its "
                                       f"running level {level.fitness:.3f}")
    if expected.search_because and not evidence.searched:
        return Verdict(Outcome.UNSETTLED, expected.search_because, Needs.SEARCH)
    if evidence.tied:
        summary = f"{len(evidence.tied)} distinct answers within {rules.tie_ratio:.2f} in consistency"
        if not evidence.searched:
            return Verdict(Outcome.UNSETTLED, f"near-tie: {summary}", Needs.SEARCH)
        if evidence.near:
            return Verdict(Outcome.NEAR_TIE, f"symmetric scene: {summary}, the one next to the motion prediction kept")
        return Verdict(Outcome.AMBIGUOUS, f"ambiguous: {summary}, none next to the motion prediction")
    unconfirmed = "no running level yet" if level is None else shortfall(leader, level, rules)
    confirmed = not unconfirmed
    if not (confirmed and evidence.expected):
        why = unconfirmed or f"{evidence.offset[0]:.2f} m from the motion prediction"
        if not evidence.searched:
            return Verdict(Outcome.UNSETTLED, f"unconfirmed: {why}", Needs.SEARCH)
        if not (confirmed or evidence.expected or (level is None and not expected.moving)):
            return Verdict(Outcome.FAILED, f"unconfirmed: {why}, {evidence.offset[0]:.2f} m / "
                                           f"{np.degrees(evidence.offset[1]):.1f} deg from the motion prediction")
        if level is None and leader.consistency < 0.0:
            return Verdict(Outcome.FAILED, f"unconfirmed: {why}, more of the scan off the map "
                                           f"({1 - leader.coverage:.3f}) than on its surfaces ({leader.fitness:.3f})")
        if level is None and not expected.moving and evidence.outranked:
            return Verdict(Outcome.FAILED, f"unconfirmed: {why}, no motion known, and the search's more consistent "
                                           "answers put the scan where the map's last scan saw empty space")
    if evidence.displaced and not evidence.neighbours_checked:
        return Verdict(Outcome.UNSETTLED, f"{evidence.offset[0]:.2f} m from the predicted position",
                       Needs.NEIGHBOURS)
    degenerate = leader.signals.conditioning < rules.min_conditioning
    if not degenerate and weak_view(leader, rules) and not evidence.neighbours_checked:
        return Verdict(Outcome.UNSETTLED, "weakly constrained view", Needs.NEIGHBOURS)
    if not (leader.explained or evidence.last_scan_checked):
        return Verdict(Outcome.UNSETTLED, "not yet polished from the map's last scan", Needs.LAST_SCAN)
    if degenerate:
        return Verdict(Outcome.DEGENERATE, f"degenerate (conditioning {leader.signals.conditioning:.4f}): a "
                                           "direction the view barely constrains")
    if level is not None and evidence.disputed:  # no level: nothing has joined the map since its one scan
        why = "disputed: the map's last scan alone leads from the answer to a distinct one"
        if not evidence.searched:
            return Verdict(Outcome.UNSETTLED, why, Needs.SEARCH)
        return Verdict(Outcome.NEAR_TIE, f"{why}, the map's answer kept")
    return Verdict(Outcome.ACCEPTED)
