"""The state of a campaign store on disk: tasks done, left and failed
(:func:`campaign_status`, :class:`CampaignStatus`).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .lock import lock_holder
from .store import CampaignStore


@dataclass(frozen=True)
class CampaignStatus:
    """Progress of a stored campaign (see :func:`campaign_status`).

    ``n_done`` counts the finished tasks (flagged done and verified against their
    checksums); ``n_damaged`` the tasks flagged done whose stored chunks are missing,
    truncated or altered (a rerun recomputes them); ``running`` describes the run holding
    the store's lock (``"pid 123 on host h since ..."``), or is None.
    """

    path: str
    name: str
    spec_hash: str
    n_tasks: int
    n_done: int
    dims: Mapping[str, int]
    done_by_pattern: Mapping[str, int]
    tasks_per_pattern: int
    input_hashes: Mapping[str, str]
    versions: Mapping[str, str]
    total_task_s: float
    n_damaged: int = 0
    running: str | None = None

    @property
    def complete(self) -> bool:
        """Whether every task is stored (and none damaged)."""
        return self.n_done == self.n_tasks

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return {
            "path": self.path,
            "name": self.name,
            "spec_hash": self.spec_hash,
            "n_tasks": self.n_tasks,
            "n_done": self.n_done,
            "complete": self.complete,
            "dims": dict(self.dims),
            "done_by_pattern": dict(self.done_by_pattern),
            "tasks_per_pattern": self.tasks_per_pattern,
            "input_hashes": dict(self.input_hashes),
            "versions": dict(self.versions),
            "total_task_s": self.total_task_s,
            "n_damaged": self.n_damaged,
            "running": self.running,
        }


def campaign_status(results: str | os.PathLike[str]) -> CampaignStatus:
    """Progress and provenance of a campaign store.

    Raises
    ------
    StoreError
        If the store is missing, not a campaign store or damaged.
    """
    import json

    store = CampaignStore.open(results)
    scan = store.scan()
    mask = scan.finished
    holder = lock_holder(results)
    spec = store.spec_dict()
    names = [p["name"] for p in spec["pattern"]]
    dims = dict(
        zip(("pattern", "angle", "subset", "noise", "blur", "rep"), mask.shape, strict=True)
    )
    per_pattern = {n: int(mask[i].sum()) for i, n in enumerate(names)}
    try:
        times = store.read("time_s")
    except Exception:  # a damaged time_s chunk (counted in n_damaged)
        times = np.full(mask.shape, np.nan)
    return CampaignStatus(
        path=str(results),
        name=spec["campaign"]["name"],
        spec_hash=str(store.attrs["spec_hash"]),
        n_tasks=int(mask.size),
        n_done=int(mask.sum()),
        dims=dims,
        done_by_pattern=per_pattern,
        tasks_per_pattern=int(mask[0].size),
        input_hashes=json.loads(store.attrs.get("input_hashes", "{}")),
        versions=json.loads(store.attrs.get("versions", "{}")),
        total_task_s=float(np.nansum(np.where(mask, times, np.nan))),
        n_damaged=scan.n_damaged,
        running=holder.describe() if holder is not None else None,
    )
