"""A reconstruction job's exports (solvers/reconstruction/export.py: COLMAP's text model, PLY),
written in an export process (app.processes), not in the API process.

An export reads the whole result and decodes it (some 25 bytes of Python objects a byte of JSON),
then writes its files a point at a time, holding the interpreter lock throughout: for a result of
100,000 points (96 MB), about 18 s of CPU for COLMAP's model and 3 s for PLY each. Eight at once in
the API process held +5.4 GB and kept another key's GET /v1/jobs waiting 17 s. Here the export
process reads the result from Redis itself, and the API process sends the export's bytes on; at
most GEOCERT_MAX_CONCURRENT_EXPORTS run at once in an API process (its gate), one key's at most
GEOCERT_MAX_CONCURRENT_EXPORTS_PER_KEY.
"""

from __future__ import annotations

from geocert.app import processes
from geocert.app.errors import ApiProblem


def ready() -> None:
    """An export process's first task: what an export imports, imported."""
    from geocert.app.api import deps  # noqa: F401
    from geocert.solvers.reconstruction import export  # noqa: F401


def export_job(job_id: str, format: str, binary: bool, environment: dict[str, str]) -> tuple:
    """In an export process: ("export", bytes, media type, file name suffix), or an error carried
    (processes.carried). The heap's free pages go back to the system after each."""
    from geocert.app.api.deps import get_store
    from geocert.solvers.reconstruction import export

    processes.use(environment)
    try:
        try:
            result = get_store().result(job_id) or {}
            if result.get("kind") != "reconstruction":
                raise ApiProblem(422, f"job {job_id} is a {result.get('kind')} job: only reconstruction results are "
                                      "exported", "format")
            if format == "colmap":
                return "export", export.colmap_zip(result), "application/zip", "-colmap.zip"
            return ("export", export.ply(result, binary), "application/octet-stream" if binary else "text/plain",
                    ".ply")
        except Exception as exc:  # the errors an export answers with; anything else is a bug, raised
            return processes.carried_or_raised(exc)
    finally:
        processes.give_back_memory()
