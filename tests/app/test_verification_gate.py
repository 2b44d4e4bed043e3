"""POST /v1/certificates/verify: at most GEOCERT_MAX_CONCURRENT_VERIFICATIONS at once in a
process, counted before the body is read (a body is parsed into some 25 times its size)."""

from __future__ import annotations

import asyncio

from geocert.app.main import VerificationGate


def run_two(limit: int, path: str, gate_options: dict | None = None, keys: tuple = (None, None),
            bodies: list | None = None) -> list[int]:
    """Two requests to ``path`` (with X-API-Key ``keys``), the first held inside the app until the
    second is answered: the statuses in the order the requests were made (the answers' bodies
    added to ``bodies``)."""

    async def main() -> list[int]:
        release, entered = asyncio.Event(), asyncio.Event()
        statuses: list[list[int]] = [[], []]

        async def app(scope, receive, send):
            if not entered.is_set():  # the first request is held until the second is answered
                entered.set()
                await release.wait()
            await send({"type": "http.response.start", "status": 200, "headers": []})
            await send({"type": "http.response.body", "body": b"{}"})

        gate = VerificationGate(app, **({"limit": limit} | (gate_options or {})))

        def request(k: int):
            async def receive():
                return {"type": "http.request", "body": b"{}", "more_body": False}

            async def send(message):
                if message["type"] == "http.response.start":
                    statuses[k].append(message["status"])
                    if k == 1:
                        release.set()
                elif bodies is not None and message.get("body"):
                    bodies.append(message["body"])
            headers = [] if keys[k] is None else [(b"x-api-key", keys[k].encode())]
            scope = {"type": "http", "method": "POST", "path": path, "headers": headers}
            return gate(scope, receive, send)

        first = asyncio.create_task(request(0))
        await entered.wait()
        second = asyncio.create_task(request(1))
        await asyncio.wait_for(asyncio.gather(first, second), 5)
        return [s[0] for s in statuses]

    return asyncio.run(main())


def test_a_verification_beyond_the_limit_is_refused_before_its_body_is_read():
    assert run_two(1, "/v1/certificates/verify") == [200, 429]


def test_other_paths_and_no_limit_pass():
    assert run_two(1, "/v1/jobs") == [200, 200]
    assert run_two(0, "/v1/certificates/verify") == [200, 200]


def test_one_key_holds_at_most_its_share_of_orientations_verifications_and_exports():
    """Each gate the service installs (GEOCERT_MAX_CONCURRENT_*) lets one key hold at most its
    share (GEOCERT_MAX_CONCURRENT_*_PER_KEY, 1 by default) of the places, so one key cannot hold
    every orientation, verification or export process while another key's waits: its second is
    refused with a 429 naming the per-key limit, and another key's is let in."""
    from geocert.app.main import create_app

    gates = {str(m.kwargs.get("path", VerificationGate.PATH)): m.kwargs for m in create_app().user_middleware
             if m.cls is VerificationGate}
    paths = {"/v1/certificates/verify": "/v1/certificates/verify", "/v1/orient": "/v1/orient",
             "export": "/v1/jobs/0123/export"}
    for name, path in paths.items():
        (options,) = [kwargs for gated, kwargs in gates.items() if name in gated]
        assert options["per_key"] == 1, name
        options = options | {"limit": 2}  # room for two: only the per-key share refuses
        bodies: list[bytes] = []
        assert run_two(2, path, options, keys=("one", "one"), bodies=bodies) == [200, 429], name
        assert options["per_key_variable"].encode() in bodies[0], bodies
        assert run_two(2, path, options, keys=("one", "other")) == [200, 200], name


def test_a_large_request_gives_the_heaps_free_pages_back(monkeypatch):
    """glibc keeps what a request freed in its arenas: after a request whose body or answer passes
    the threshold (here 100 bytes), GiveBackMemory hands the free pages back (malloc_trim), once;
    after a small one it does not."""
    from geocert.app import main, processes

    trims = []
    monkeypatch.setattr(processes, "give_back_memory", lambda: trims.append(1))

    def answer(size: int):
        async def app(scope, receive, send):
            await receive()
            await send({"type": "http.response.start", "status": 200, "headers": []})
            await send({"type": "http.response.body", "body": b"x" * size})
        return app

    async def one(app, body: bytes) -> None:
        async def receive():
            return {"type": "http.request", "body": body, "more_body": False}

        async def send(message):
            pass
        await main.GiveBackMemory(app, above=100)({"type": "http", "method": "POST", "path": "/", "headers": []},
                                                  receive, send)

    asyncio.run(one(answer(10), b"{}"))
    assert trims == []
    asyncio.run(one(answer(10), b"x" * 200))
    assert trims == [1]
    asyncio.run(one(answer(200), b"{}"))
    assert trims == [1, 1]
