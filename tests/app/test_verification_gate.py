"""POST /v1/certificates/verify: at most GEOCERT_MAX_CONCURRENT_VERIFICATIONS at once in a
process, counted before the body is read (a body is parsed into some 25 times its size)."""

from __future__ import annotations

import asyncio

from geocert.app.main import VerificationGate


def run_two(limit: int, path: str) -> list[int]:
    """Two requests to ``path``, the first held inside the app until the second is answered: the
    statuses in the order the requests were made."""

    async def main() -> list[int]:
        release, entered = asyncio.Event(), asyncio.Event()
        statuses: list[list[int]] = [[], []]

        async def app(scope, receive, send):
            if not entered.is_set():  # the first request is held until the second is answered
                entered.set()
                await release.wait()
            await send({"type": "http.response.start", "status": 200, "headers": []})
            await send({"type": "http.response.body", "body": b"{}"})

        gate = VerificationGate(app, limit)

        def request(k: int):
            async def receive():
                return {"type": "http.request", "body": b"{}", "more_body": False}

            async def send(message):
                if message["type"] == "http.response.start":
                    statuses[k].append(message["status"])
                    if k == 1:
                        release.set()
            scope = {"type": "http", "method": "POST", "path": path, "headers": []}
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
