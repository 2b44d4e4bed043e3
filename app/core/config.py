"""Settings, from GEOCERT_* environment variables (pydantic-settings)."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

from pydantic_settings import BaseSettings, SettingsConfigDict


class Settings(BaseSettings):
    model_config = SettingsConfigDict(env_prefix="GEOCERT_", env_file=None)

    # A real Redis (redis://, rediss:// or unix://). Unset: `geocert serve` starts an embedded one.
    redis_url: str | None = None
    # Where the embedded Redis keeps its socket and append-only file.
    data_dir: Path = Path("var")
    # Largest request body accepted, in bytes (413 beyond it).
    max_body_bytes: int = 32 * 1024 * 1024
    # Most items (tracks) in one job (422 beyond it).
    max_items_per_job: int = 200_000
    # Items per queued task: batches are split into chunks that run in parallel across workers.
    chunk_size: int = 100
    # Seconds between progress events of one chunk.
    progress_interval_s: float = 0.25
    # Seconds a finished job (and its events) is kept.
    result_ttl_s: int = 7 * 24 * 3600


@lru_cache
def get_settings() -> Settings:
    return Settings()
