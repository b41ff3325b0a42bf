"""The virtual view: the boom in a browser (``server.py``, ``web/``), fed by a run file
or a live co-simulation (``live.py``), and rendered to a video for reports
(``export.py``).  What is drawn comes from ``frames.py``."""
from .frames import BoomMechanism, LinkageMechanism, Run, live_frame, load_run, mechanism_of

__all__ = ["Run", "BoomMechanism", "LinkageMechanism", "mechanism_of", "live_frame", "load_run"]
