"""The map's unvouched scans: what a live node takes into its map before the global search has vouched for it.

A live scan whose answer waits for the search where the search does not fit its budget (:mod:`.steps.scan_budget`)
is published flagged *unconfirmed*. Left out of the map, such answers starve it on a sensor that turns fast: the
next scans look where the map has nothing, fail, and restart it. So the map takes the answer in, *unvouched*, and
the search checks it beside the worker (:mod:`.side_search`) against the map as the scan saw it, with the scan's
whole plan, while the worker aligns the newer scans. Until a check settles, every step the map's unvouched part
could mislead is flagged unconfirmed too (and joins the map, unvouched). The checks run one at a time, oldest
first, each against a map whose earlier scans are all vouched for (as offline, where each scan is searched in
turn); a check

- **confirms** the scan (its plan stands within the node's precision of the answer taken in): the scan is
  vouched for, and so are those after it up to the next one unconfirmed on its own evidence (they stood on their
  own evidence against a map whose every scan is now vouched for); the node then vouches for these steps late
  (:attr:`~.steps.alignment_step.AlignmentStep.vouched_late`), and the next one's check starts. Where the scan
  *owed* the search (the step before it failed, or a check took the map back) and had no time for it, the steps
  after it stood without the search they would have run offline, on a map the node had just lost or rolled back:
  the check vouches for the scan alone, and those steps stay flagged (the map keeps them);
- or **places it elsewhere** (a standing answer distinct from it): the map goes back to what it was before the
  scan, takes the scan in where the check placed it, and the current pose moves by the same correction (the
  motion since kept); the steps since stood on a map the node no longer holds, so the next scan runs the search;
- or **stands by nothing** (failed, ambiguous, near-tie): the map goes back to what it was before the scan, and
  the next scan runs the search.

Offline every scan runs its whole plan: nothing is unvouched.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from cemnet_ros.pipeline.map.voxel_map import VoxelMap
from cemnet_ros.pipeline.side_search import SideSearch
from cemnet_ros.pipeline.steps.frame import Frame
from cemnet_ros.pipeline.steps.registration import Registered


@dataclass(frozen=True)
class Check:
    """What an unconfirmed scan's check needs: the map before the scan went in (and where the map last grew
    then), and the scan's plan against it."""

    map_before: VoxelMap
    T_last_insert_before: Optional[np.ndarray]
    register: Callable[[], Registered]


@dataclass(frozen=True)
class UnvouchedScan:
    """A scan the map took in unvouched, at ``T_inserted`` (T_odom_sensor of its reference time); ``check``:
    its own check where its own evidence left it unconfirmed (None: it is unvouched for the map's sake only)."""

    stamp_ns: int
    frame: Frame
    T_inserted: np.ndarray
    check: Optional[Check]
    owed_search: bool = False  # the scan owed the global search (a failed step or check before it), had no time


class Unvouched:
    """The map's unvouched scans, oldest first, and the check beside the worker."""

    def __init__(self) -> None:
        self._scans: list[UnvouchedScan] = []
        self._side: SideSearch[UnvouchedScan] = SideSearch()

    def __len__(self) -> int:
        return len(self._scans)

    @property
    def oldest(self) -> UnvouchedScan:
        """The oldest unvouched scan: the map before it is the map the node last vouched for."""
        return self._scans[0]

    @property
    def before(self) -> Check:
        """The check of the oldest scan: the map before it (the one the node last vouched for), and where that map
        last grew."""
        check = self._scans[0].check
        assert check is not None  # see :meth:`add`
        return check

    def add(self, scan: UnvouchedScan) -> None:
        """The map took ``scan`` in, unvouched (the first one always has a check of its own)."""
        assert self._scans or scan.check is not None
        self._scans.append(scan)

    def start_check(self) -> None:
        """Check the oldest scan beside the worker, unless a check runs."""
        if self._scans and not self._side.busy:
            self._side.start(self._scans[0], self.before.register)

    def finished(self) -> Optional[tuple[UnvouchedScan, Registered]]:
        """The check that ended since the last call, with its scan (None: none ended)."""
        return self._side.finished()

    def vouched(self, scan: UnvouchedScan) -> list[int]:
        """``scan`` is confirmed: it, the scans before it, and those after it that have no check of their own
        leave; the stamps vouched for (not those after a scan that owed the search, see the module)."""
        count = self._scans.index(scan) + 1
        confirmed = count
        while count < len(self._scans) and self._scans[count].check is None:
            count += 1
        left, self._scans = self._scans[:count], self._scans[count:]
        return [s.stamp_ns for s in left[:confirmed if scan.owed_search else count]]

    def clear(self) -> None:
        """None is left (the map went back, or restarted); a running check's result is dropped."""
        self._scans = []
        self._side.forget()
