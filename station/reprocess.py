"""Re-processing archived sessions: their frames measured and fitted again with the current pipeline.

When the pipeline improves (every string measured to its ends, a better model choice), the
frames a session kept are worth more than the profiles it stored. :func:`reprocess_focus`
re-does one focus setting of one archived session directory exactly as the executor did
(:mod:`station.session.executor`): the frames of each orientation's accepted attempt averaged
(checked against the manifest's SHA-256), measured (:func:`station.session.processing.measure_shot`
with the session's ``pipeline.t``) and checked (strings found at the expected angle), fitted by
:func:`station.session.profile_steps.fit_focus` (leave one orientation out, the session's bootstrap
and seed; a twin compared, not fitted), and judged against the session's ``qa`` thresholds. It only *reads* the session
directory (no lock, nothing written), so an archive can be read-only, and it never raises for
a bad session: a :class:`FocusResult` carries the new profile or a one-line ``failure``.

Jobs are :class:`FocusJob` (one focus setting of one session, the unit a worker runs);
:func:`plan_jobs` lists them — every focus setting for which the session stored a profile.
:func:`run_jobs` runs them here, on a local process pool, or on a Dask cluster
(``scheduler="tcp://HOST:PORT"``; ``dask.distributed`` is imported only then), and the results
do not depend on where they ran: each job limits BLAS to one thread (:func:`_one_thread`) so
that its floating-point sums are the same on every worker. The session directories must be
readable at the same path on every worker (a shared file system).

:func:`finish_session` turns a session's results into the profiles to store: each new profile's
provenance (``Profile.provenance.extra["reprocess"]``) names the session, the profile it
re-processes (its store id when this store holds it) and the software versions before and now;
its store key is ``<session_dir>#reprocess-<version>`` (:func:`reprocess_key`), so the old
profile stays, and re-processing again with the same version replaces the earlier result
instead of adding another.
"""

from __future__ import annotations

import contextlib
import hashlib
import logging
import math
import os
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from pipeline.fitspec import parse_choice
from pipeline.model_file import read_model_file
from station import SOFTWARE, __version__
from station.calibration import GIVEN_BY_CONFIG, GIVEN_ON_COMMAND_LINE, focus_profile
from station.config import ConfigError, load_config
from station.errors import HarpError
from station.pool import WorkerPool
from station.profile import Profile, Verdict
from station.provenance import make_provenance
from station.qa.verdicts import Measurements, qa_verdict
from station.session import layout
from station.session.colour import KEY as COLOUR
from station.session.colour import frames_cfa, session_colour
from station.session.directory import SessionError, lost_manifest, read_manifest
from station.session.frame_files import decode_frame
from station.session.layout import CONFIG_COPY, MANIFEST, SESSION_FILE
from station.session.processing import average_frames, measure_shot, shot_problems
from station.session.profile_steps import fit_focus
from station.session.records import FrameSaved, ManifestReads, QARecorded, parse
from station.store import StoreError

BLAS_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")

PRELOAD = ["station.reprocess", "station.calibration", "pipeline.fit", "pipeline.measure", "station.qa.verdicts"]
"""Modules the local pool's forkserver imports once, so that each worker starts warm."""


class ReprocessError(HarpError, RuntimeError):
    """Re-processing cannot start (no scheduler, no pool); ``str()`` is one line."""


# ------------------------------------------------------------------ jobs
@dataclass(frozen=True)
class FocusJob:
    """One focus setting of one archived session: what a worker re-processes.

    ``spec``: a fit label (:func:`pipeline.fitspec.parse`), ``"auto"`` for the cross-validated
    choice, or None for what the session's configuration names. ``field``: ``pipeline.field`` instead of the
    configuration's (:data:`pipeline.fitspec.FIELD_CHOICES`: whether a residual field is added where it holds on
    unseen orientations), or None for the configuration's (a session recorded before the setting existed: the
    default, ``auto``).
    """

    session_dir: str
    focus_idx: int
    spec: str | None = None
    field: str | None = None


@dataclass(frozen=True)
class OldProfile:
    """The profile the session stored for a focus setting, as its directory records it."""

    profile: Profile | None
    store_id: int | None
    verdict: str | None
    software: str | None


@dataclass(frozen=True)
class FocusResult:
    """What re-processing one focus setting came to: the new profile (judged), or a failure."""

    job: FocusJob
    focus: float | None
    profile: Profile | None
    old: OldProfile | None
    failure: str | None = None
    seconds: float = 0.0
    worker: str = ""


def _one_line(text: object) -> str:
    return " ".join(str(text).split())


def _software_versions() -> dict[str, str]:
    import cv2
    import numpy
    import scipy

    return {
        "harp-station": __version__,
        "numpy": numpy.__version__,
        "scipy": scipy.__version__,
        "opencv": cv2.__version__,
    }


# --------------------------------------------------- the session, read only
class ArchivedSession(ManifestReads):
    """A session directory opened for reading only: its meta, manifest records and configuration.

    Unlike :class:`station.session.directory.SessionDir` it takes no lock and writes nothing
    (no torn line cut, no temporary removed): an archive may be read-only, or being read by
    many workers at once. Raises ValueError (one line naming the file) for what cannot be read.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        import json

        self.path = Path(path)
        meta_file = self.path / SESSION_FILE
        if not meta_file.is_file():
            raise ValueError(f"{self.path}: not a session directory (no {SESSION_FILE})")
        try:
            self.meta = json.loads(meta_file.read_text())
            if not isinstance(self.meta, dict):
                raise ValueError("not a JSON object")
        except (OSError, ValueError) as exc:
            raise ValueError(f"{meta_file}: cannot read ({_one_line(exc)})") from None
        try:
            self.lines, _ = read_manifest(self.path / MANIFEST)
            self.typed = parse(self.lines)
        except (OSError, SessionError) as exc:
            raise ValueError(_one_line(exc)) from None
        try:
            self.config = load_config(self.path / CONFIG_COPY, base_dir=self.meta.get("base_dir"))
        except ConfigError as exc:
            raise ValueError(_one_line(exc)) from None

    def read_frame(self, record: FrameSaved) -> Any:
        """The frame of a record, checked against the manifest's SHA-256."""
        path = self.path / record.file
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise ValueError(f"{path}: cannot read ({exc.strerror or exc})") from None
        if hashlib.sha256(data).hexdigest() != record.sha256:
            raise ValueError(f"{path}: checksum does not match the session manifest (damaged frame)")
        try:
            return decode_frame(data)
        except ValueError as exc:
            raise ValueError(f"{path}: {exc}") from None

    def stored_focus(self) -> dict[int, int | None]:
        """``{focus_idx: store id}`` of every focus setting the session stored a profile for."""
        return {int(f): pid for f, pid in self.stored_ids().items()}

    def old_profile(self, f: int) -> OldProfile:
        """The profile the session stored for focus setting ``f`` (its model file) and its verdict."""
        profile = None
        try:
            profile = Profile.from_model_file(read_model_file(self.path / layout.profile_file(f)))
        except (OSError, ValueError):
            pass
        judged = [r for r in self.of_type(QARecorded) if r.focus_idx == f]
        verdict = str(judged[-1].verdict) if judged else None
        if profile is not None and profile.qa is None and judged:  # the session's verdict, from its manifest
            last = judged[-1]
            profile = profile.with_(qa=Verdict(str(last.verdict), tuple(last.reasons or ()), dict(last.metrics or {})))
        stored = self.stored_focus().get(f)
        software = profile.provenance.software if profile is not None else None
        if software is None and self.meta.get("software_version"):
            software = f"harp-station {self.meta['software_version']}"
        return OldProfile(profile, stored, verdict, software)


def plan_jobs(
    session_dirs: Iterable[str | os.PathLike[str]], spec: str | None = None, field: str | None = None
) -> tuple[list[FocusJob], dict[str, str]]:
    """The jobs of some session directories — one per focus setting the session stored a profile
    for, each with ``spec`` and ``field`` (:class:`FocusJob`) — and ``{session_dir: failure}`` for those that
    cannot be re-processed at all."""
    jobs: list[FocusJob] = []
    failed: dict[str, str] = {}
    for d in session_dirs:
        path = str(Path(d).resolve())
        try:
            s = ArchivedSession(path)
        except ValueError as exc:
            failed[path] = str(exc)
            continue
        stored = s.stored_focus()
        if not stored:
            lost = lost_manifest(Path(path), s.lines)
            failed[path] = lost or f"{path}: the session stored no profile (nothing to re-process)"
            continue
        jobs += [FocusJob(path, f, spec, field) for f in sorted(stored)]
    return jobs, failed


# ------------------------------------------------------------ one job
def _one_thread() -> Any:
    """A context in which BLAS/OpenMP use one thread, so that sums are the same on every worker."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - threadpoolctl is a dependency
        import contextlib

        return contextlib.nullcontext()
    return threadpool_limits(1)


def reprocess_focus(job: FocusJob) -> FocusResult:
    """Re-measure and re-fit one focus setting of an archived session (module docstring).
    Never raises for a bad session: the result's ``failure`` says what went wrong, in one line."""
    import socket

    t0 = time.perf_counter()
    worker = f"{socket.gethostname()}:{os.getpid()}"
    try:
        with _one_thread():
            focus, profile, old = _reprocess(job, worker)
    except ValueError as exc:
        return FocusResult(job, None, None, None, _one_line(exc), time.perf_counter() - t0, worker)
    except Exception as exc:  # a bug or an unforeseen fault: said in one line, the other jobs go on
        return FocusResult(
            job, None, None, None, f"{type(exc).__name__}: {_one_line(exc)}", time.perf_counter() - t0, worker
        )
    return FocusResult(job, focus, profile, old, None, time.perf_counter() - t0, worker)


def _spec(job: FocusJob, config: Any) -> Any:
    return config.pipeline.spec if job.spec is None else parse_choice(job.spec)


def _reprocess(job: FocusJob, worker: str) -> tuple[float, Profile, OldProfile]:
    if not os.path.isdir(job.session_dir):  # it was there when the jobs were planned, where the command runs
        raise ValueError(
            f"{job.session_dir}: no such directory where the job ran ({worker}); every worker must see the "
            "session directories at the same path (a shared file system) until harp reprocess ends"
        )
    s = ArchivedSession(job.session_dir)
    cfg = s.config
    if job.field is not None:  # the profile records the pipeline it was fitted with
        cfg = replace(cfg, pipeline=replace(cfg.pipeline, field=job.field))
    f = job.focus_idx
    if not 0 <= f < len(cfg.focus_settings):
        raise ValueError(f"{s.path}: no focus setting #{f} in its configuration")
    focus = float(cfg.focus_settings[f])
    where = f"{s.path.name} focus {focus:g}"
    n = cfg.capture.frames_per_orientation
    shots = []
    frame_files: list[Path] = []
    size: tuple[int, int] | None = None
    for o, commanded in enumerate(cfg.capture.angles_deg):
        records = s.frames(f, o)
        if len(records) != n:
            raise ValueError(f"{where}: orientation {o} has {len(records)} of its {n} frames in the manifest")
        images = [s.read_frame(r) for r in records]
        h, w = images[0].shape
        if size is None:
            size = (w, h)
        elif size != (w, h):
            raise ValueError(f"{where}: orientation {o} frames are {w}x{h}, the others {size[0]}x{size[1]}")
        m = measure_shot(average_frames(images), cfg.pipeline, frames_cfa(records))
        stage = (records[-1].meta or {}).get("stage_deg")
        expected = cfg.station.harp.expected_angle(commanded if stage is None else stage)
        problems = shot_problems(m, expected, cfg.capture.checks)
        if problems:
            raise ValueError(f"{where}: orientation {o}: {'; '.join(problems)}")
        shots.append(list(m.lines))
        frame_files += [s.path / r.file for r in records]
    assert size is not None
    w, h = size
    cal = fit_focus(f, cfg, shots, (w, h), map, s, spec=_spec(job, cfg))
    if cal.failure or not cal.fit:
        raise ValueError(f"{where}: the fit failed: {cal.failure}")
    fitted = [shots[o] for o in cfg.capture.fitted]  # what the fit took (a twin is compared, not fitted)
    old = s.old_profile(f)
    colour = session_colour(s, f, cal.fit.model, cfg)  # a colour camera's TCA and vignetting, made again
    profile = focus_profile(
        cal,
        w,
        h,
        cfg,
        f,
        provenance=make_provenance(frame_files, t=cfg.pipeline.t, command="harp reprocess", station=cfg.station.id),
        given_by=GIVEN_ON_COMMAND_LINE if job.spec else GIVEN_BY_CONFIG,
        details={
            "session_model_file": str(s.path / layout.profile_file(f)),
            **({COLOUR: colour} if colour is not None else {}),
        },
        judge=lambda p: qa_verdict(
            p, cfg.qa, measurements=Measurements(fitted, f"{s.path.name}, re-measured, focus index {f}")
        ),
    )
    return focus, profile, old


# --------------------------------------------------------- where it runs
def run_jobs(
    jobs: Sequence[FocusJob],
    *,
    workers: int = 1,
    scheduler: str | DaskCluster | None = None,
    on_result: Callable[[FocusResult], None] = lambda _r: None,
) -> list[FocusResult]:
    """Run ``jobs`` and return their results in the jobs' order.

    ``scheduler`` (``tcp://HOST:PORT``, or a cluster :func:`dask_cluster` connected and checked): on that Dask
    cluster; else on a local process pool of ``workers`` processes (``workers <= 1``: in this process). ``on_result`` is called as each
    result arrives (in the order they finish). A local worker that dies is that job's failure, as a job every
    Dask worker that ran it died of is (Dask runs a killed worker's jobs again elsewhere first). A scheduler
    that cannot be reached, is not one, has no worker or a worker without this version of harp station raises
    :class:`ReprocessError` before any job is sent; the scheduler lost, or every worker gone, mid-run
    :class:`ClusterLost` (the results told ``on_result`` before it stand).
    """
    if not jobs:
        return []
    if isinstance(scheduler, DaskCluster):
        return _gather(scheduler.client, jobs, scheduler.scheduler, on_result)
    if scheduler is not None:
        with dask_cluster(scheduler) as cluster:
            return _gather(cluster.client, jobs, scheduler, on_result)
    if workers <= 1:
        out = []
        for j in jobs:
            r = reprocess_focus(j)
            on_result(r)
            out.append(r)
        return out
    return _run_pool(jobs, min(workers, len(jobs)), on_result)


def _run_pool(jobs: Sequence[FocusJob], workers: int, on_result: Callable[[FocusResult], None]) -> list[FocusResult]:
    from concurrent.futures import as_completed

    results: dict[int, FocusResult] = {}
    with WorkerPool(workers, PRELOAD) as pool:  # Ctrl-C: the jobs not started dropped, the running ones stopped
        futures = {fut: i for i, fut in enumerate(pool.submit_all(reprocess_focus, jobs))}
        for fut in as_completed(futures):
            i = futures[fut]
            try:
                r = fut.result()
            except Exception as exc:  # BrokenProcessPool: a worker died (killed, out of memory)
                r = FocusResult(
                    jobs[i], None, None, None, f"worker process failed: {type(exc).__name__}: {_one_line(exc)}"
                )
            results[i] = r
            on_result(r)
    return [results[i] for i in range(len(jobs))]


def probe_scheduler(scheduler: str, timeout: float = 10.0) -> None:
    """Refuse at once (:class:`ReprocessError`, one line) a scheduler address that is not
    ``tcp://HOST:PORT`` or where nothing listens, instead of Dask's retries until its timeout; and, within
    ``timeout``, one where something else listens (a Dask scheduler speaks first, its handshake: Dask's client
    waits for it forever, e.g. at the scheduler's dashboard port)."""
    import socket
    from urllib.parse import urlsplit

    u = urlsplit(scheduler)
    try:
        host, port = u.hostname, u.port
    except ValueError:
        host, port = None, None
    if u.scheme != "tcp" or not host or port is None:
        raise ReprocessError(f"--scheduler {scheduler}: give the Dask scheduler's address as tcp://HOST:PORT")
    try:
        sock = socket.create_connection((host, port), timeout=timeout)
    except OSError as exc:
        raise ReprocessError(f"cannot reach the Dask scheduler at {scheduler}: {exc.strerror or exc}") from None
    with sock:
        try:
            spoke = bool(sock.recv(1))
        except OSError:  # the timeout, a reset
            spoke = False
    if not spoke:
        raise ReprocessError(
            f"{scheduler} is not a Dask scheduler (something listens there, but it sent no Dask handshake in "
            f"{timeout:g} s); give the scheduler's port (8786 unless it was started with another; 8787 is its dashboard)"
        )


NO_WORKERS_S = 60.0
"""How long :func:`run_jobs` waits on a Dask cluster without a worker (none at the start, or every one gone
mid-run and none back) before it stops: a scheduler waits for workers forever."""

_WORKER_CHECK = "__import__('station.reprocess').__version__"
"""Evaluated on each Dask worker before the jobs are sent (a string, so that a worker without harp station
can run it): the version of harp station it runs, or the ImportError it meets (a job sent to such a worker
fails to unpickle, and the worker dies of it, again and again)."""


_DIGEST_CHECK = "__import__('station.reprocess', fromlist=['code_digest']).code_digest()"
"""Evaluated on each Dask worker that runs this version: :func:`code_digest` of the code it runs."""

CODE_PACKAGES = ("pipeline", "station", "drivers")
"""The packages whose files make the code a profile is computed by (:func:`code_digest`)."""


def code_digest() -> str:
    """The SHA-256 (hex) of the Python files of :data:`CODE_PACKAGES` as this process runs them (their paths inside
    the package and their bytes): two processes with the same digest compute the same profiles, whether they run
    a checkout or an installed wheel of it (data files, which a wheel may hold fewer of, are left out). A checkout
    changed but not released keeps its version number, not its digest (some 20 ms)."""
    import importlib.util

    h = hashlib.sha256()
    for name in CODE_PACKAGES:
        spec = importlib.util.find_spec(name)
        tops = spec.submodule_search_locations if spec is not None else None
        for top in tops or ():
            root = Path(top)
            for path in sorted(root.rglob("*.py")):
                h.update(f"{name}/{path.relative_to(root).as_posix()}".encode() + b"\0")
                h.update(path.read_bytes())
    return h.hexdigest()


class ClusterLost(ReprocessError):
    """The Dask cluster went away mid-run (its scheduler killed, every worker gone): the jobs not finished are
    lost. ``what`` happened and what ``to_do`` before running the command again for them."""

    def __init__(self, what: str, to_do: str) -> None:
        super().__init__(f"{what}; {to_do}, then run harp reprocess again for the sessions not stored")
        self.what, self.to_do = what, to_do


def _killed(job: FocusJob, exc: Any) -> str:
    last = getattr(getattr(exc, "last_worker", None), "address", "?")
    tried = getattr(exc, "allowed_failures", 0) + 1
    return (
        f"{job.session_dir}: focus setting #{job.focus_idx}: every Dask worker that ran it died ({tried} tried, "
        f"the last {last}: killed, or out of memory?); see that worker's log, then run harp reprocess again "
        "for this session"
    )


def _check_workers(client: Any, scheduler: str) -> None:
    """Refuse (:class:`ReprocessError`, one line) a cluster with no worker after :data:`NO_WORKERS_S`, or a
    worker that cannot import harp station, runs another version of it, or other code under this version
    (:func:`code_digest`)."""
    try:
        client.wait_for_workers(1, timeout=NO_WORKERS_S)
    except TimeoutError:
        raise ReprocessError(
            f"the Dask scheduler at {scheduler} has no worker (none joined in {NO_WORKERS_S:g} s); "
            f"start some: dask worker {scheduler} --nthreads 1"
        ) from None
    seen = client.run(eval, _WORKER_CHECK, on_error="return")
    for addr, got in sorted(seen.items()):
        if isinstance(got, BaseException):
            raise ReprocessError(
                f"Dask worker {addr} cannot import harp station ({type(got).__name__}: {_one_line(got)}); "
                f"run every worker with harp station {__version__} installed, as this command"
            )
        if got != __version__:
            raise ReprocessError(
                f"Dask worker {addr} runs harp station {got}, this command {__version__}; "
                "run the same version on every worker (its profiles would be another version's)"
            )
    ours = code_digest()
    digests = client.run(eval, _DIGEST_CHECK, on_error="return")
    for addr, got in sorted(digests.items()):
        if got != ours:
            raise ReprocessError(
                f"Dask worker {addr} runs other code than this command under the same version {__version__} (its "
                "files of harp station differ: another checkout, or one changed since); run every worker with the "
                "same code as this command (its profiles would not be this code's)"
            )


@dataclass(frozen=True)
class DaskCluster:
    """A connected Dask ``client`` of the scheduler at ``scheduler``, its workers checked (:func:`dask_cluster`)."""

    client: Any
    scheduler: str


@contextlib.contextmanager
def dask_cluster(scheduler: str) -> Iterator[DaskCluster]:
    """Connect to the Dask scheduler at ``scheduler`` (``tcp://HOST:PORT``) and check it can run the jobs; the
    client is closed when the block ends. Refused (:class:`ReprocessError`, one line, before any job is sent,
    so that a command can ask before it opens its store): a scheduler that cannot be reached or is not one, none
    of whose workers joins within :data:`NO_WORKERS_S`, or a worker without this version and code of harp station
    (:func:`_check_workers`)."""
    probe_scheduler(scheduler)
    from dask.distributed import Client

    _silence_distributed()
    try:
        client = Client(scheduler, timeout="10s", set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        raise ReprocessError(f"cannot reach the Dask scheduler at {scheduler}: {_one_line(exc)}") from None
    try:
        _check_workers(client, scheduler)
        yield DaskCluster(client, scheduler)
    finally:
        client.close(timeout=10)


def _silence_distributed() -> None:
    """Dask's loggers silent in this process from now on: its client logs a lost scheduler as tracebacks (the
    ``distributed.client`` logger, which has a level of its own), also from its own thread after it is closed;
    :func:`run_jobs` says each fault in a line."""
    names = [n for n in logging.root.manager.loggerDict if n == "distributed" or n.startswith("distributed.")]
    for name in {"distributed", *names}:
        logging.getLogger(name).setLevel(logging.CRITICAL + 1)


def _gather(
    client: Any,
    jobs: Sequence[FocusJob],
    scheduler: str,
    on_result: Callable[[FocusResult], None],
) -> list[FocusResult]:
    """The jobs' results, each told ``on_result`` as it arrives (:func:`run_jobs`); :class:`ClusterLost` when
    the scheduler goes away or every worker is gone for :data:`NO_WORKERS_S`."""
    from distributed import KilledWorker, as_completed
    from distributed.client import FutureCancelledError

    lost = ClusterLost(
        f"lost the Dask scheduler at {scheduler} mid-run (killed, or its machine down?)", "start it again"
    )
    futures = client.map(reprocess_focus, list(jobs), pure=False, retries=0)
    index = {fut.key: i for i, fut in enumerate(futures)}
    results: dict[int, FocusResult] = {}
    pending = as_completed(futures, loop=client.loop)
    alone_since: float | None = None
    asked = 0.0
    while not pending.is_empty():
        done = pending.next_batch(block=False)
        if not done:
            if client.status not in ("running", "connecting"):
                raise lost
            if time.monotonic() - asked > 1.0:  # the scheduler asked about its workers once a second
                asked = time.monotonic()
                if client.scheduler_info(n_workers=-1).get("workers"):
                    alone_since = None
                elif alone_since is None:
                    alone_since = asked
                elif asked - alone_since > NO_WORKERS_S:
                    raise ClusterLost(
                        f"every Dask worker of {scheduler} is gone, and none came back in {NO_WORKERS_S:g} s",
                        f"start some (dask worker {scheduler} --nthreads 1)",
                    )
            time.sleep(0.1)
            continue
        for fut in done:
            i = index[fut.key]
            try:
                r = fut.result()
            except FutureCancelledError as exc:
                if getattr(exc, "reason", "") == "scheduler-connection-lost" or client.status != "running":
                    raise lost from None
                r = FocusResult(jobs[i], None, None, None, f"Dask cancelled the job: {_one_line(exc)}")
            except KilledWorker as exc:
                r = FocusResult(jobs[i], None, None, None, _killed(jobs[i], exc))
            except Exception as exc:  # any other fault of the cluster: the job's failure, in a line
                r = FocusResult(
                    jobs[i], None, None, None, f"Dask worker failed: {type(exc).__name__}: {_one_line(exc)}"
                )
            results[i] = r
            on_result(r)
    return [results[i] for i in range(len(jobs))]


# ------------------------------------------------- results to the store
def reprocess_key(session_dir: str) -> str:
    """The store's ``session_dir`` of a session's re-processed profiles (module docstring)."""
    return f"{session_dir}#reprocess-{__version__}"


@dataclass(frozen=True)
class SessionOutcome:
    """One session re-processed: its focus results and the profiles to store (empty if it failed)."""

    session_dir: str
    results: tuple[FocusResult, ...] = ()
    failure: str | None = None
    profiles: tuple[Profile, ...] = ()
    old_ids: tuple[int | None, ...] = ()
    new_ids: list[int | None] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return self.failure is None


def _same_focus(a: float | None, b: float | None) -> bool:
    return a is not None and b is not None and math.isclose(a, b, rel_tol=0, abs_tol=1e-9)


def old_store_profile(store: Any, old: OldProfile, session_dir: str, focus: float) -> Profile | None:
    """The store's row of the profile a session stored (by the id its manifest records), when this
    store holds it: the same lens, focus and session (by path, or by name for a moved archive)."""
    if store is None or old.store_id is None:
        return None
    p = store.profile(int(old.store_id))
    if p is None or not _same_focus(p.focus, focus) or p.provenance.session_dir is None:
        return None
    if old.profile is not None and old.profile.lens is not None and p.lens != old.profile.lens:
        return None
    if Path(p.provenance.session_dir).name != Path(session_dir).name:
        return None
    return p


def finish_session(session_dir: str, results: Sequence[FocusResult], store: Any = None) -> SessionOutcome:
    """The profiles to store for one session (none when any of its focus settings failed), each
    with the provenance of module docstring; ``store``: where the old profiles are looked up."""
    failures = [r.failure for r in results if r.failure is not None]
    if failures:
        return SessionOutcome(session_dir, tuple(results), "; ".join(dict.fromkeys(failures)))  # each once
    versions = _software_versions()
    profiles = []
    old_ids = []
    for r in results:
        assert r.profile is not None and r.old is not None and r.focus is not None
        stored = old_store_profile(store, r.old, session_dir, r.focus)
        base = stored.provenance.session_dir if stored is not None else session_dir
        assert base is not None
        old_id = stored.id if stored is not None else None
        prov = r.profile.provenance
        extra = {
            **dict(prov.extra),
            "reprocess": {
                "session": session_dir,
                "old_profile_id": old_id,
                "old_software": r.old.software,
                "old_verdict": stored.qa.verdict if stored is not None and stored.qa is not None else r.old.verdict,
                "software": SOFTWARE,
                "versions": versions,
                "worker": r.worker,
            },
        }
        profiles.append(r.profile.with_(provenance=replace(prov, session_dir=reprocess_key(base), extra=extra)))
        old_ids.append(old_id)
    return SessionOutcome(session_dir, tuple(results), None, tuple(profiles), tuple(old_ids))


class SessionCollector:
    """Gathers the focus results of each session as they arrive (any order, from any worker) and,
    when a session's last one arrives, finishes it (:func:`finish_session`: ``store`` names the old
    profiles it holds) and stores its new profiles in ``store`` — not with ``dry_run`` (nor without a
    store). ``outcomes`` holds every session finished so far; ``on_outcome`` is told each one. A store
    error while storing is the session's failure (the profiles stored before it stay)."""

    def __init__(
        self,
        jobs: Sequence[FocusJob],
        store: Any = None,
        on_outcome: Callable[[SessionOutcome], None] = lambda _o: None,
        *,
        dry_run: bool = False,
    ) -> None:
        self.store, self.on_outcome, self.dry_run = store, on_outcome, dry_run
        self.expected: dict[str, int] = {}
        for j in jobs:
            self.expected[j.session_dir] = self.expected.get(j.session_dir, 0) + 1
        self.arrived: dict[str, list[FocusResult]] = {}
        self.outcomes: dict[str, SessionOutcome] = {}

    def __call__(self, r: FocusResult) -> None:
        got = self.arrived.setdefault(r.job.session_dir, [])
        got.append(r)
        if len(got) < self.expected[r.job.session_dir]:
            return
        got.sort(key=lambda x: x.job.focus_idx)
        outcome = finish_session(r.job.session_dir, got, self.store)
        if outcome.ok and self.store is not None and not self.dry_run:
            try:
                for p in outcome.profiles:
                    outcome.new_ids.append(self.store.put_profile(p))
            except StoreError as exc:
                outcome = replace(outcome, failure=_one_line(exc), profiles=(), old_ids=(), new_ids=[])
        self.outcomes[r.job.session_dir] = outcome
        self.on_outcome(outcome)
