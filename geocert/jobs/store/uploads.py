"""A large body's items, written a batch at a time under a temporary key before its job exists
(``app.streamed.upload_items``); the key becomes the job's item list when the job is created
(``create(items_key=...)``), or is dropped."""

from __future__ import annotations

import uuid

from geocert.jobs.store.base import StoreBase


class Uploads(StoreBase):
    @staticmethod
    def upload_key() -> str:
        """A new temporary key for an upload's items."""
        return f"geocert:upload:{uuid.uuid4().hex}"

    def append_upload(self, key: str, texts: list[str], ttl_s: int) -> None:
        """Append items' JSON texts to the upload ``key``, which expires ``ttl_s`` from now (gone by
        itself if the API dies before the job is made)."""
        pipe = self.r.pipeline()
        pipe.rpush(key, *texts)
        pipe.expire(key, ttl_s)
        pipe.execute()

    def drop_upload(self, key: str) -> None:
        """Remove the upload ``key`` (nothing when it is gone, e.g. already the job's item list)."""
        self.r.delete(key)
