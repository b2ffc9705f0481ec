"""Replay a ROS1 bag to rosbridge clients, in real time: a recorded sensor stream for the ROS adapters' tests.

A rosbridge server (rosbridge_server, on a ROS machine) turns topics into rosbridge's JSON protocol over a
websocket; ``roslibpy`` (vical's ROS adapters) is its client. This stands in for a ROS machine playing a bag
(``rosbag play`` beside ``rosbridge_server``): it speaks the protocol's topic operations (``subscribe``,
``unsubscribe``; the others are ignored), and once every
topic of the bag has a subscriber it publishes the bag's messages at their recorded pace as rosbridge encodes
them for ROS 1 (``uint8[]`` as base64 text, stamps as ``secs``/``nsecs``). After the last message the topics
stay silent, as a sensor's do when its cable is pulled.

    python tests/rosbridge_replay.py data.bag          # prints "port <N>" once it listens on 127.0.0.1:<N>
"""

from __future__ import annotations

import argparse
import asyncio
import base64
import contextlib
import json
import sys
import time
from dataclasses import fields, is_dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.rosbag1 import Reader
from websockets.asyncio.server import ServerConnection, serve
from websockets.exceptions import ConnectionClosed

from vical.io.bag import ros1_typestore

TIME_TYPE = "builtin_interfaces/msg/Time"


def as_rosbridge(value: Any) -> Any:
    """A deserialised rosbags message (or field) as rosbridge's ROS 1 JSON value."""
    if is_dataclass(value):
        if value.__msgtype__ == TIME_TYPE:
            return {"secs": int(value.sec), "nsecs": int(value.nanosec)}
        return {f.name: as_rosbridge(getattr(value, f.name)) for f in fields(value)}
    if isinstance(value, np.ndarray):
        return base64.b64encode(value.tobytes()).decode() if value.dtype == np.uint8 else value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def recorded_messages(bag: Path) -> list[tuple[int, str, Any]]:
    """Every message of ``bag`` in recorded order: (bag time [ns], topic, the message, deserialised)."""
    store = ros1_typestore()
    with Reader(bag) as reader:
        return [(t, c.topic, store.deserialize_ros1(raw, c.msgtype)) for c, t, raw in reader.messages()]


class Replay:
    """The subscribers of each topic, and the bag played to them once every topic has one."""

    def __init__(self, messages: list[tuple[int, str, Any]]) -> None:
        self.messages = messages
        self.topics = {topic for _, topic, _ in messages}
        self.subscribers: dict[str, set[ServerConnection]] = {topic: set() for topic in self.topics}
        self.all_subscribed = asyncio.Event()

    async def serve_client(self, connection: ServerConnection) -> None:
        try:
            async for text in connection:
                self.handle(connection, json.loads(text))
        finally:
            for subscribed in self.subscribers.values():
                subscribed.discard(connection)

    def handle(self, connection: ServerConnection, request: dict[str, Any]) -> None:
        topic = request.get("topic")
        if request["op"] == "subscribe" and topic in self.subscribers:
            self.subscribers[topic].add(connection)
            if all(self.subscribers.values()):
                self.all_subscribed.set()
        elif request["op"] == "unsubscribe" and topic in self.subscribers:
            self.subscribers[topic].discard(connection)

    async def play(self) -> None:
        await self.all_subscribed.wait()
        t0_bag, t0_wall = self.messages[0][0], time.monotonic()
        for t, topic, msg in self.messages:
            await asyncio.sleep(max(0.0, t0_wall + (t - t0_bag) * 1e-9 - time.monotonic()))
            text = json.dumps({"op": "publish", "topic": topic, "msg": as_rosbridge(msg)})
            for connection in list(self.subscribers[topic]):
                with contextlib.suppress(ConnectionClosed):  # a client gone: it leaves the subscribers in serve_client
                    await connection.send(text)


async def main(bag: Path, port: int) -> None:
    replay = Replay(recorded_messages(bag))
    async with serve(replay.serve_client, "127.0.0.1", port, max_size=None) as server:
        print(f"port {server.sockets[0].getsockname()[1]}", flush=True)
        await replay.play()
        await asyncio.Future()  # the topics stay silent until the process is stopped


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("bag", type=Path)
    p.add_argument("--port", type=int, default=0, help="0: any free port (printed)")
    args = p.parse_args()
    try:
        asyncio.run(main(args.bag, args.port))
    except KeyboardInterrupt:
        sys.exit(130)
