"""A calibration session: what to capture, capturing it, and the session directory.

* :mod:`station.session.plan` — the capture plan as data (steps; re-captures decided
  from each shot's check result);
* :mod:`station.session.executor` — the one executor performing the plan on a camera
  and a turntable (retries, device recovery), emitting typed manifest records; the work of its
  steps in :mod:`station.session.shot_checks` (frames and shots checked),
  :mod:`station.session.profile_steps` (a focus setting fitted and stored) and
  :mod:`station.session.camera_matrix` (the board views checked, the camera matrix fitted);
* :mod:`station.session.records` — those records (one dataclass per manifest kind), and
  how every reader reads them back typed (``parse``, ``ManifestReads``);
* :mod:`station.session.progress` — progress bars and the summary table, a subscriber
  to the records;
* :mod:`station.session.directory` — the session directory (atomic frames, the
  append-only manifest, resume) and :mod:`station.session.layout`, the one place
  that names every path in it;
* :mod:`station.session.processing` — averaging and checking shots;
  :mod:`station.session.evidence` — measurements and uncertainty maps kept as ``.npz``;
* :mod:`station.session.devices`, :mod:`station.session.simulated` — opening the
  configured (or simulated) camera and turntable.

A whole session (the executor, then QA and the report, then ``finished``) is
:mod:`station.session_run`, above this package and the QA (:mod:`station.qa`).
"""
