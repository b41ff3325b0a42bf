"""Test campaigns and fleets: many recordings identified and diagnosed on Dask.

``boomfmi campaign MANIFEST --out DIR`` reads a manifest (:mod:`.manifest`: machine,
date, role, recording, optional sidecar), runs each machine's date as one case of
``identify`` and ``diagnose`` (:mod:`.case`) on ``dask.distributed`` (:mod:`.engine`:
a LocalCluster or a scheduler by address; results written as they complete, a re-run
resumes, a failed case is reported, a lost worker's case retried), and relates the
dates (:mod:`.trend`: each parameter's trend with its intervals, each effect's size,
flags where they move) in ``campaign.json`` and ``campaign.html`` (:mod:`.report`).
:mod:`.fleet` makes a virtual fleet with known changes for tests and the demo.
"""
from .engine import Engine, run_campaign, run_cases
from .manifest import Case, Manifest, ManifestError, read_manifest, write_manifest

__all__ = ["Case", "Engine", "Manifest", "ManifestError", "read_manifest", "run_campaign", "run_cases",
           "write_manifest"]
