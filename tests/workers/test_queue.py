"""The queue's use of Celery from the API: its tasks named, never imported."""

from __future__ import annotations

import json
import subprocess
import sys


# In a process whose Celery broker is the test's Redis: a job of 3 chunks created with its tasks
# collected into the job's transaction (JobStore.create's enqueue), another published the usual
# way after its creation, and one refused by the active-job limit; then what the queue holds.
_COLLECT = """
import json, sys, redis
import redis.connection
from geocert.workers import queue
from geocert.workers.priorities import queue_lists
from geocert.jobs.store import JobStore
store = JobStore.from_url(sys.argv[1])
request = {"kind": "triangulation", "data": {"tracks": [{}] * 5}, "options": {}}
writes = [0]
send = redis.connection.AbstractConnection.send_packed_command
def counted(self, *args, **kwargs):
    writes[0] += 1
    return send(self, *args, **kwargs)
queue.task_commands({"id": "warm", "kind": "triangulation", "chunks": [(0, 1)], "task_ids": ["w"]}, None)
store.r.ping()  # connections made before counting
redis.connection.AbstractConnection.send_packed_command = counted
collected = store.create("triangulation", request, 5, 2, "someone", active_limit=1, chunk_key="tracks",
                         item_time_bound_s=2.0, enqueue=lambda meta: queue.task_commands(meta, "request-1"))
writes_to_create = writes[0]
redis.connection.AbstractConnection.send_packed_command = send
refused = store.create("triangulation", request, 5, 2, "someone", active_limit=1, chunk_key="tracks",
                       enqueue=lambda meta: queue.task_commands(meta, None))
store.release("someone", collected["id"])
published = store.create("triangulation", request, 5, 2, "someone", chunk_key="tracks", item_time_bound_s=2.0)
queue.submit_chunks({**published, "id": collected["id"], "task_ids": [t + "-again" for t in collected["task_ids"]]},
                    "request-1")
task_code = sorted(m for m in sys.modules if m in ("geocert.workers.tasks", "geocert.workers.webhooks",
                                                  "geocert.workers.signals", "geocert.workers.reaper"))
print(json.dumps({"can_collect": queue.can_collect(), "collected": collected["task_ids"], "refused": refused,
                  "task_code": task_code,
                  "writes_to_create": writes_to_create,
                  "messages": [m for name in queue_lists("celery") for m in store.r.lrange(name, 0, -1)]}))
"""


def _task(message: str) -> dict:
    """A queued Celery message as a worker reads it: its headers, arguments and properties
    (its priority among them), without what differs between two publishes of the same task (its
    id, correlation id and delivery tag, its group's id)."""
    import base64

    message = json.loads(message)
    args, kwargs, embed = json.loads(base64.b64decode(message["body"]))
    headers = {k: v for k, v in message["headers"].items() if k not in ("id", "root_id", "group", "origin")}
    properties = {k: v for k, v in message["properties"].items() if k not in ("correlation_id", "delivery_tag")}
    return {"id": message["headers"]["id"], "task": [headers, args, kwargs, embed, properties,
                                                      {k: v for k, v in message.items() if k not in ("headers", "body",
                                                                                                    "properties")}]}


def test_tasks_collected_into_the_jobs_transaction_are_the_messages_a_publish_queues(tmp_path):
    from geocert.workers.redis_server import start_embedded_redis

    process, url = start_embedded_redis(tmp_path)
    try:
        env = {"GEOCERT_REDIS_URL": url, "PATH": "/usr/bin:/bin"}
        out = subprocess.run([sys.executable, "-c", _COLLECT, url], capture_output=True, text=True, env=env, timeout=120)
    finally:
        process.terminate()
        process.wait(timeout=10)
    assert out.returncode == 0, out.stderr[-2000:]
    seen = json.loads(out.stdout.strip().splitlines()[-1])
    assert seen["can_collect"] and seen["refused"] is None
    assert seen["task_code"] == []  # the tasks named, not imported
    assert seen["writes_to_create"] == 1  # the job and its tasks: one round trip to Redis
    tasks = [_task(message) for message in seen["messages"]]
    by_id = {task["id"]: task["task"] for task in tasks}
    assert len(tasks) == 6 and set(by_id) == {*seen["collected"], *(t + "-again" for t in seen["collected"])}
    for task_id in seen["collected"]:  # the refused job queued nothing; the admitted one its 3 chunks
        assert by_id[task_id] == by_id[task_id + "-again"]
    assert sorted(by_id[t][1] for t in seen["collected"]) == [
        [by_id[seen["collected"][0]][1][0], start, stop, "request-1"] for start, stop in ((0, 2), (2, 4), (4, 5))]


# The event loop's way (queue.loop_producer, JobStore.create_async): a job of 3 chunks and one
# refused by the active-job limit, created through an asyncio client with their tasks made by the
# loop's producer; the sockets written while making the tasks, the round trips of the creation,
# then what the queue and the store hold.
_ON_THE_LOOP = """
import asyncio, json, socket, sys
import redis.asyncio, redis.asyncio.connection
from geocert.workers import queue
from geocert.workers.priorities import queue_lists
from geocert.jobs.store import JobStore
url = sys.argv[1]
store = JobStore.from_url(url)
request = {"kind": "triangulation", "data": {"tracks": [{}] * 5}, "options": {}}
queue.ready_loop_producer()
producer = queue.loop_producer()
meta = {"id": "x" * 32, "kind": "triangulation", "chunks": [(0, 2), (2, 4), (4, 5)], "task_ids": ["a", "b", "c"]}
sent = [0]
methods = {name: getattr(socket.socket, name) for name in ("send", "sendall", "sendmsg", "connect")}
def counting(name):
    def call(self, *args, **kwargs):
        sent[0] += 1
        return methods[name](self, *args, **kwargs)
    return call
for name in methods:
    setattr(socket.socket, name, counting(name))
commands = queue.task_commands(meta, "request-1", producer)
for name, method in methods.items():
    setattr(socket.socket, name, method)
writes = [0]
send = redis.asyncio.connection.AbstractConnection.send_packed_command
async def counted(self, *args, **kwargs):
    writes[0] += 1
    return await send(self, *args, **kwargs)
async def main():
    client = redis.asyncio.Redis.from_url(url, decode_responses=True)
    await client.ping()  # its connection made before counting
    redis.asyncio.connection.AbstractConnection.send_packed_command = counted
    collected = await store.create_async(client, "triangulation", request, 5, 2, "someone", active_limit=1,
                                         chunk_key="tracks", item_time_bound_s=2.0,
                                         enqueue=lambda meta: queue.task_commands(meta, "request-1", producer))
    writes_to_create = writes[0]
    redis.asyncio.connection.AbstractConnection.send_packed_command = send
    refused = await store.create_async(client, "triangulation", request, 5, 2, "someone", active_limit=1,
                                       chunk_key="tracks", enqueue=lambda meta: queue.task_commands(meta, None, producer))
    return collected, refused, writes_to_create
collected, refused, writes_to_create = asyncio.run(main())
store.release("someone", collected["id"])
published = store.create("triangulation", request, 5, 2, "someone", chunk_key="tracks", item_time_bound_s=2.0)
queue.submit_chunks({**published, "id": collected["id"], "task_ids": [t + "-again" for t in collected["task_ids"]]},
                    "request-1")
print(json.dumps({"sent_making_tasks": sent[0], "commands": len(commands), "collected": collected["task_ids"],
                  "refused": refused, "writes_to_create": writes_to_create,
                  "jobs": sorted(store.r.zrange(store.owner_key("someone", "jobs"), 0, -1)),
                  "expected_jobs": sorted([collected["id"], published["id"]]),
                  "request": store.request(collected["id"]) == request,
                  "messages": [m for name in queue_lists("celery") for m in store.r.lrange(name, 0, -1)]}))
"""


def test_tasks_made_on_the_event_loop_send_nothing_and_join_the_jobs_transaction(tmp_path):
    """The API's event loop makes a small job's tasks with a producer readied beforehand
    (queue.loop_producer): making them touches no socket (the loop never waits on the broker),
    and JobStore.create_async queues them in the job's own transaction, one round trip, the same
    messages a publish queues; a job refused by its key's limit leaves no task and no record."""
    from geocert.workers.redis_server import start_embedded_redis

    process, url = start_embedded_redis(tmp_path)
    try:
        env = {"GEOCERT_REDIS_URL": url, "PATH": "/usr/bin:/bin"}
        out = subprocess.run([sys.executable, "-c", _ON_THE_LOOP, url], capture_output=True, text=True, env=env,
                             timeout=120)
    finally:
        process.terminate()
        process.wait(timeout=10)
    assert out.returncode == 0, out.stderr[-2000:]
    seen = json.loads(out.stdout.strip().splitlines()[-1])
    assert seen["sent_making_tasks"] == 0 and seen["commands"] == 3
    assert seen["refused"] is None and seen["writes_to_create"] == 1
    assert seen["jobs"] == seen["expected_jobs"] and seen["request"]  # the refused job left no record
    tasks = [_task(message) for message in seen["messages"]]
    by_id = {task["id"]: task["task"] for task in tasks}
    assert len(tasks) == 6 and set(by_id) == {*seen["collected"], *(t + "-again" for t in seen["collected"])}
    for task_id in seen["collected"]:
        assert by_id[task_id] == by_id[task_id + "-again"]


# A fresh Redis: a job's tasks made twice with the same producer (the loop's), kombu's declarations
# counted; then whether the queue's binding (without which the Redis transport finds no queue for a
# message) exists.
_DECLARED_ONCE = """
import json, sys
import kombu.messaging, redis
from geocert.workers import queue
declarations = []
declare = kombu.messaging.Producer.maybe_declare
def counted(self, entity, *args, **kwargs):
    declarations.append(entity.name)
    return declare(self, entity, *args, **kwargs)
kombu.messaging.Producer.maybe_declare = counted
from geocert.workers.celery_app import celery_app
producer = celery_app.producer_pool.acquire(block=True)
meta = {"id": "j" * 32, "kind": "triangulation", "chunks": [(0, 2), (2, 4), (4, 5)], "task_ids": ["a", "b", "c"]}
first = queue.task_commands(meta, None, producer)
declared_first = list(declarations)
second = queue.task_commands(meta, None, producer)
print(json.dumps({"declared_first": declared_first, "declared_second": declarations[len(declared_first):],
                  "commands": [len(first), len(second)],
                  "bindings": sorted(redis.Redis.from_url(sys.argv[1], decode_responses=True).keys("_kombu.binding*"))}))
"""


def test_the_queue_is_declared_by_the_first_tasks_made_on_a_connection_and_not_asked_again(tmp_path):
    """kombu would be asked to declare the task queue at every message (and find it in its cache,
    at a third of a small job's cost of making its messages): it is asked once a connection, the
    first time, which still declares it on a fresh Redis."""
    from geocert.workers.redis_server import start_embedded_redis

    process, url = start_embedded_redis(tmp_path)
    try:
        env = {"GEOCERT_REDIS_URL": url, "PATH": "/usr/bin:/bin"}
        out = subprocess.run([sys.executable, "-c", _DECLARED_ONCE, url], capture_output=True, text=True, env=env,
                             timeout=120)
    finally:
        process.terminate()
        process.wait(timeout=10)
    assert out.returncode == 0, out.stderr[-2000:]
    seen = json.loads(out.stdout.strip().splitlines()[-1])
    assert seen["declared_first"] == ["celery"] and seen["declared_second"] == []
    assert seen["commands"] == [3, 3]
    assert "_kombu.binding.celery" in seen["bindings"]
