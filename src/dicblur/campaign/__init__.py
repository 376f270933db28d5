"""Campaigns: the synthetic blur experiment at scale, on Dask, stored as labelled data.

A campaign is a grid of tasks (pattern x angle x subset x noise x blur W x repetition),
each one blurred, noisy image correlated against its reference (the paper's Sections III
and VI). The pieces:

- :mod:`~dicblur.campaign.spec`: the TOML spec, validated (:func:`load_spec`).
- :mod:`~dicblur.campaign.tasks`: batches and deterministic task seeds.
- :mod:`~dicblur.campaign.simulate`: the task itself (:func:`simulate_batch`).
- :mod:`~dicblur.campaign.store`: the Zarr store, written batch by batch, resumable.
- :mod:`~dicblur.campaign.engine`: serial or Dask execution (:func:`run_campaign`); any
  independent tasks: :func:`run_tasks` (:mod:`~dicblur.campaign.mapping`), on a Dask
  cluster through :mod:`~dicblur.campaign.cluster`; a store's progress:
  :func:`campaign_status` (:mod:`~dicblur.campaign.status`).
- :mod:`~dicblur.campaign.chunks`: a resumable store of finished chunks of any job
  (:class:`ChunkStore`, used by ``dicblur track --workers``).
- :mod:`~dicblur.campaign.calibrate`: the paper's sweep on one pattern plus the model fits.

Nothing here imports Dask, Zarr or xarray at module level: they are imported when a
campaign runs or a store is opened.
"""

from __future__ import annotations

from .chunks import ChunkStore
from .cluster import check_scheduler_address
from .engine import RunSummary, run_campaign
from .mapping import TasksSummary, run_tasks
from .simulate import directional_sssig, simulate_batch
from .spec import CampaignSpec, PatternSpec, load_spec, parse_spec
from .status import CampaignStatus, campaign_status
from .store import VARIABLES, CampaignStore, export_csv, open_results
from .tasks import Batch, input_hashes, iter_batches, make_pattern, task_seed

__all__ = [
    "VARIABLES",
    "Batch",
    "CampaignSpec",
    "CampaignStatus",
    "CampaignStore",
    "ChunkStore",
    "PatternSpec",
    "RunSummary",
    "TasksSummary",
    "campaign_status",
    "check_scheduler_address",
    "directional_sssig",
    "export_csv",
    "input_hashes",
    "iter_batches",
    "load_spec",
    "make_pattern",
    "open_results",
    "parse_spec",
    "run_campaign",
    "run_tasks",
    "simulate_batch",
    "task_seed",
]
