"""Campaigns: a whole range test as one resumable run on Dask (docs/campaign.md).

:func:`run_campaign` runs a manifest (:func:`load_manifest`) into a folder: stage one of
every shot, the sphere calibration, single fits, each group's multi-fit, hold study and gap
diagnosis, then the report page; :func:`campaign_status` says what is done, failed or stale;
:func:`group_fit` gives a group's stored multi-fit (what ``cadra campaign plan`` plans from);
:func:`read_tables` and :func:`query` read the campaign database with pandas.
"""

from cadra.campaign.database import query, read_tables
from cadra.campaign.manifest import Manifest, ManifestError, load_manifest
from cadra.campaign.run import CampaignError, RunSummary, run_campaign
from cadra.campaign.status import campaign_status, export_tables, group_fit

__all__ = ["CampaignError", "Manifest", "ManifestError", "RunSummary", "campaign_status",
           "export_tables", "group_fit", "load_manifest", "query", "read_tables", "run_campaign"]
