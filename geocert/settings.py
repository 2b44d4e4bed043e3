"""Settings, from GEOCERT_* environment variables (pydantic-settings): one module that the API,
the workers and the command line all read (the workers import nothing of the web layer).

Every setting is listed with its variable and default in docs/operations.md, "Configuration".
"""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path

from pydantic import model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict


class Settings(BaseSettings):
    model_config = SettingsConfigDict(env_prefix="GEOCERT_", env_file=None)

    # A real Redis (redis://, rediss:// or unix://). Unset: `geocert serve` starts an embedded one.
    redis_url: str | None = None
    # Where the embedded Redis keeps its socket and append-only file.
    data_dir: Path = Path("var")
    # API keys, comma-separated: the keys themselves or "sha256:<hex digest>". Empty: no
    # authentication, and the service listens on loopback only.
    api_keys: str = ""
    # Largest request body accepted, in bytes (413 beyond it).
    max_body_bytes: int = 32 * 1024 * 1024
    # A job body larger than this, of a kind with an item list, is read item by item (its items
    # checked and stored a batch at a time), so that the API holds about the body's size, not
    # Python objects for every number (app.streamed).
    stream_threshold_bytes: int = 1 << 20
    # A body up to this size is submitted on the API's event loop (app.job_submission.submit_on_loop),
    # a larger one in its thread pool; 0: every submission in the pool.
    submit_on_loop_bytes: int = 32 << 10
    # Most items (tracks or maps) in one job (413 beyond it).
    max_items_per_job: int = 200_000
    # Most observations or correspondences, summed over a job's items (413 beyond it).
    max_points_per_job: int = 2_000_000
    # Certificate verifications (POST /v1/certificates/verify) running at once in one API
    # process (429 beyond it; 0: unlimited): each may hold some 25 times its body in memory.
    max_concurrent_verifications: int = 2
    # ... and of one key's among them (its X-API-Key header), so one key cannot hold every place.
    max_concurrent_verifications_per_key: int = 1
    # Orientations (POST /v1/orient) running at once in one API process (429 beyond it; 0:
    # unlimited): each may hold some 700 MB and 12 s of CPU at max_view_points_per_job.
    max_concurrent_orientations: int = 2
    max_concurrent_orientations_per_key: int = 1  # ... and of one key's among them
    # Exports of a job's result (GET /v1/jobs/{id}/export) running at once in one API process, and
    # of one key's (429 beyond either; 0: unlimited): each is written in an export process, which
    # may hold some 700 MB and 18 s of CPU for a reconstruction of 100,000 points.
    max_concurrent_exports: int = 2
    max_concurrent_exports_per_key: int = 1
    # Requests per minute one key may make to /v1 (429 beyond it; 0: unlimited).
    rate_limit_per_minute: int = 1200
    # Jobs one key may have queued or running at once (429 beyond it; 0: unlimited).
    max_active_jobs_per_key: int = 100
    # Bytes one key's jobs that exist (queued, running, or ended and not yet expired or deleted)
    # may hold in Redis, each counted as its request's bytes and at least 16 KiB, and once it ends
    # its stored result's bytes too (compressed, fragments included) (429 beyond it; 0: unlimited). Results are kept result_ttl_s after a job ends, and a key at the rate limit
    # stored some 700 MB an hour of one-track jobs, or 20 GB an hour of 5.5 MB ones.
    max_stored_bytes_per_key: int = 1 << 30
    # A job's budget, computed from its request before anything of it is decoded or built (each
    # kind's request_figures; 413 naming the figure and its limit beyond one). See docs/operations.md,
    # "Limits", for what each bounds.
    # Pixels of a reconstruction's photos, from their headers: all of them (the worker holds them
    # decoded, a byte each), and the largest (feature detection holds about 240 bytes a pixel of
    # one image at a time: 12 Mpx is about 2.9 GB).
    max_image_pixels_per_job: int = 100_000_000
    max_image_pixels: int = 12_000_000
    # Views (cameras) of an autocalibration (each adds rows to every conic program of both stages),
    # and of a reconstruction (its views or photos).
    max_autocalibration_views: int = 50
    max_reconstruction_views: int = 300
    # Cameras times points: an autocalibration's chirality rows, /v1/orient's dense arrays.
    max_view_points_per_job: int = 4_000_000
    # Points in one map (resection, homography): each of its conic programs has a row per point,
    # and its first programs do not stop at its time limit (5,000 points with time_limit_s 2: 15 s;
    # 20,000: 65 s and 0.8 GB; 200,000: 3.3 GB, then the solver process died).
    max_points_per_map: int = 20_000
    # A bilinear job's basis: shapes times points (each frame's programs grow with both).
    max_basis_points_per_job: int = 50_000
    # stereo_lines: segments in one image of a frame, or lines matched in one frame pair. Matching
    # compares every pair of segments and solves assignments (cubic): about 0.4 s of CPU a pair at
    # 500 segments, 2 s at 1000, 11 s at 2000. It asks the clock between blocks and before each
    # assignment, so a pair keeps its time_limit_s to within one assignment.
    max_segments_per_frame: int = 1000
    # Memory of one solver process, in MiB (its address space, set when it starts): a task that
    # needs more fails its job with the reason, and that process goes on with the next task.
    # 0: no limit.
    worker_memory_mb: int = 4096
    # Fairness, with API keys: one key's tasks run on every live solver process but this many (at
    # least one), so that another key's job starts at once however many jobs the first has queued;
    # a task over its key's share waits in the queue, its job queued. 0: no share (first come,
    # first served). Without keys (one user, on loopback) there is no share.
    solvers_kept_for_others: int = 1
    # Server-side maxima of the per-item options time_limit_s and max_nodes (422 beyond them).
    max_item_time_limit_s: float = 60.0
    max_item_nodes: int = 100_000
    # Server-side maximum of a many-item job's time limit in all, the option job_time_limit_s of
    # triangulation, resection, homography, bilinear and stereo_lines (422 beyond; a default above
    # it is lowered to it): its items share that one clock, so a job of any size ends near it.
    max_job_time_limit_s: float = 600.0
    # Items per queued task: batches are split into chunks that run in parallel. Each kind has
    # its own default (100 tracks, 1 map); GEOCERT_CHUNK_SIZES (JSON, by kind) overrides it.
    chunk_sizes: dict[str, int] = {}
    # A task starts no new item after this many seconds; the rest of its chunk is queued as a
    # new task (so that a large batch is shared between workers as it runs).
    chunk_time_budget_s: float = 20.0
    # A job ends by its own time limits (each kind's time_limit_s: per item, per stage, per point),
    # keeping its best answer. A task running this many seconds past what those limits allow it
    # (the work between the solvers' clock checks: setup, checks, storing) is stopped as a last
    # resort and its job fails with the reason, keeping what it finished: first cooperatively (at
    # the solvers' next check), then by Celery's soft time limit 30 s later, then by its hard one
    # (the process killed) 30 s after that. Never re-queued.
    task_time_margin_s: float = 120.0
    # Seconds after its worker's last heartbeat (every 2 s) before Redis hands a task the worker
    # held to another worker (the worker died). A live worker's tasks are never handed on.
    visibility_timeout_s: int = 10
    # Seconds between progress events of one chunk.
    progress_interval_s: float = 0.25
    # Seconds a finished job (and its events) is kept.
    result_ttl_s: int = 7 * 24 * 3600
    # Key for the HMAC-SHA256 signature of webhook deliveries (X-Geocert-Signature). Empty: a
    # random one is made once and kept in Redis for every process (`geocert webhook-secret`).
    webhook_secret: str = ""
    # Webhook delivery attempts and the first retry delay (doubling each time).
    webhook_attempts: int = 6
    webhook_backoff_s: float = 2.0
    # Each attempt ends within this many seconds in all (connecting, sending, the answer's status),
    # however slowly the receiver sends.
    webhook_timeout_s: float = 10.0
    # With API keys, deliveries one key may have in flight at once (0: no share): a webhook
    # worker has 8 threads, and one key's slow receivers held every one of them, so that another
    # key's webhooks waited behind all of its attempts. A delivery over its key's share is
    # deferred (not counted as an attempt).
    webhook_deliveries_per_key: int = 4
    # Webhooks go only to public addresses; networks (comma-separated addresses or CIDR blocks,
    # e.g. "127.0.0.1/32,10.1.0.0/16") the operator allows besides.
    webhook_allowed_networks: str = ""
    # A connection must complete a request's headers within this many seconds of opening (or of
    # its previous response), else it is closed (slow-header clients).
    header_timeout_s: float = 10.0
    # API processes `geocert serve` runs on its port (each an event loop of its own, one core at
    # most; what a request needs from another is in Redis). `--api-processes` overrides it.
    api_processes: int = 1
    # Event streams (SSE) one key may hold open at once in one API process, or one client address
    # when no keys are configured (429 beyond it; 0: unlimited).
    max_streams_per_key: int = 100
    # Seconds between heartbeat comments on an idle event stream (under any proxy's read timeout).
    stream_heartbeat_s: float = 10.0
    # On SIGTERM: event streams end at once (telling clients to reconnect); requests still running
    # after this many seconds are cancelled and the API exits.
    shutdown_timeout_s: float = 5.0

    @model_validator(mode="after")
    def _leases_outlive_heartbeats(self) -> "Settings":
        if self.visibility_timeout_s < 6:
            raise ValueError(f"GEOCERT_VISIBILITY_TIMEOUT_S ({self.visibility_timeout_s}) must be at least 6: three "
                             "of the workers' 2 s heartbeats, which renew their tasks' leases")
        return self


# The figures kinds report of a request (their request_figures: kinds/base.py), what each counts,
# and the setting that bounds it.
BUDGETS = {
    "image_pixels": ("max_image_pixels_per_job", "pixels in the job's photos (read from their headers)"),
    "largest_image_pixels": ("max_image_pixels", "pixels in one photo (read from its header)"),
    "autocalibration_views": ("max_autocalibration_views", "views in one job"),
    "reconstruction_views": ("max_reconstruction_views", "views in one job"),
    "view_points": ("max_view_points_per_job", "views times points in one job"),
    "basis_points": ("max_basis_points_per_job", "basis shapes times points in one job"),
    "map_points": ("max_points_per_map", "points in one map"),
    "segments_per_frame": ("max_segments_per_frame", "segments in one image of a frame (or lines in one pair)"),
}


def over_budget(figures: dict[str, tuple[int, str]]) -> tuple[str, str] | None:
    """The first figure over its limit: (the reason, naming the figure, its value, the limit and its
    variable; the field it comes from). None when every figure is within its limit."""
    settings = get_settings()
    for figure, (value, field) in figures.items():
        name, counted = BUDGETS[figure]
        limit = getattr(settings, name)
        if value > limit:
            return f"{value} {counted}: over this server's limit of {limit} (GEOCERT_{name.upper()})", field
    return None


def chunk_size_for(kind) -> int:
    """Items per queued task for a kind: GEOCERT_CHUNK_SIZES's entry, else the kind's default."""
    return max(1, int(get_settings().chunk_sizes.get(kind.name, kind.chunk_size)))


@lru_cache
def get_settings() -> Settings:
    return Settings()


def redis_url() -> str:
    """The Redis the service keeps its jobs in and queues its tasks on: GEOCERT_REDIS_URL (also read
    from the environment directly, since `geocert serve` sets it for its embedded Redis after the
    settings may have been read)."""
    url = get_settings().redis_url or os.environ.get("GEOCERT_REDIS_URL")
    if not url:
        raise RuntimeError("GEOCERT_REDIS_URL is not set (geocert serve sets it for its embedded Redis)")
    return url
