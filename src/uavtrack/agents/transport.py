"""Transports: how the programs of a swarm reach each other, behind one interface.

* `MemoryTransport`: an in-process bus, for tests and for `uavtrack swarm --transport
  memory`: every program runs in a thread of one process; publishing calls the
  subscribers' handlers at once.
* `ZenohTransport`: Eclipse Zenoh in peer mode, one session per OS process, explicit
  endpoints, multicast scouting off, no router or daemon; liveliness tokens tell the
  others when a program's process is gone.

Keys live under ``uavtrack/<run id>/``, so two swarms never hear each other. A
`Mailbox` keeps what a program received, decoded, and lets it wait for what it needs
with a deadline.
"""

from __future__ import annotations

import json
import re
import threading
import time
from collections.abc import Callable
from typing import Any

from .messages import Hello, Message, Radio, Sense, Tick, decode


class Transport:
    """Publish bytes under a key, subscribe to a key prefix, announce and watch liveness."""

    def publish(self, key: str, payload: bytes) -> None:
        raise NotImplementedError

    def subscribe(self, key: str, handler: Callable[[str, bytes], None]) -> None:
        """Call handler(key, payload) for every publication on `key`, or under it when
        `key` ends with a slash."""
        raise NotImplementedError

    def announce(self, key: str) -> None:
        """Declare this program alive under `key` until the transport closes."""

    def watch(self, key: str, on_gone: Callable[[str], None]) -> None:
        """Call on_gone(key) when the program announced as `key` (or under it, when it
        ends with a slash) is gone."""

    def alive(self, key: str) -> set[str]:
        """The keys announced now as `key` (or under it, when it ends with a slash)."""
        return set()

    def close(self) -> None:
        pass


def matches(subscription: str, key: str) -> bool:
    """Whether `key` is `subscription`, or under it when it ends with a slash."""
    return key == subscription or (subscription.endswith("/") and key.startswith(subscription))


def expression(subscription: str) -> str:
    """A subscription as a Zenoh key expression."""
    return subscription + "**" if subscription.endswith("/") else subscription


class Bus:
    """The shared medium of in-process transports."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.subscribers: list[tuple[str, Callable[[str, bytes], None]]] = []
        self.watchers: list[tuple[str, Callable[[str], None]]] = []
        self.alive: set[str] = set()
        self.published = 0
        self.bytes = 0

    def drop(self, key: str) -> None:
        """A program is gone (a test's crash): its watchers are told."""
        with self.lock:
            self.alive.discard(key)
            watchers = [w for w in self.watchers if matches(w[0], key)]
        for _, on_gone in watchers:
            on_gone(key)


class MemoryTransport(Transport):
    """A program's handle on an in-process `Bus`."""

    def __init__(self, bus: Bus) -> None:
        self.bus = bus
        self.announced: list[str] = []
        self.published = 0
        self.bytes = 0

    def publish(self, key: str, payload: bytes) -> None:
        self.published += 1
        self.bytes += len(payload)
        with self.bus.lock:
            self.bus.published += 1
            self.bus.bytes += len(payload)
            handlers = [h for sub, h in self.bus.subscribers if matches(sub, key)]
        for handler in handlers:
            handler(key, payload)

    def subscribe(self, key: str, handler: Callable[[str, bytes], None]) -> None:
        with self.bus.lock:
            self.bus.subscribers.append((key, handler))

    def announce(self, key: str) -> None:
        with self.bus.lock:
            self.bus.alive.add(key)
        self.announced.append(key)

    def watch(self, prefix: str, on_gone: Callable[[str], None]) -> None:
        with self.bus.lock:
            self.bus.watchers.append((prefix, on_gone))

    def alive(self, key: str) -> set[str]:
        with self.bus.lock:
            return {k for k in self.bus.alive if matches(key, k)}

    def close(self) -> None:
        for key in self.announced:
            self.bus.drop(key)
        self.announced = []


def zenoh_config(listen: list[str], connect: list[str], connect_timeout: float = 5.0) -> Any:
    """A peer-mode Zenoh configuration: explicit endpoints, no multicast scouting."""
    import zenoh

    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps("peer"))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("transport/shared_memory/enabled", "false")  # no SHM watchdog threads
    if listen:
        conf.insert_json5("listen/endpoints", json.dumps(listen))
    if connect:  # fail, rather than retry for ever, when nothing answers
        conf.insert_json5("connect/endpoints", json.dumps(connect))
        conf.insert_json5("connect/exit_on_failure", "true")
        conf.insert_json5("connect/timeout_ms", json.dumps(int(1000 * connect_timeout)))
    return conf


def zenoh_reason(exc: BaseException) -> str:
    """Zenoh's error message in words: without source locations, its debug wrappers
    and brackets."""
    text = " ".join(str(exc).split())
    quoted = re.search(r'msg: "([^"]*)"', text)  # a configuration error's message
    if quoted:
        text = quoted.group(1)
    text = re.sub(r" at /\S+", "", text)  # source locations
    text = re.sub(r"\bSingle\(([^)]*)\)", r"\1", text)
    text = text.replace("[", "").replace("]", "").rstrip(".")
    return text[:200] or type(exc).__name__


class ZenohTransport(Transport):
    """One Zenoh session (peer mode) of one OS process."""

    def __init__(self, listen: list[str], connect: list[str]) -> None:
        import zenoh

        zenoh.init_log_from_env_or("error")
        self.session = zenoh.open(zenoh_config(listen, connect))
        self.publishers: dict[str, Any] = {}
        self.keep: list[Any] = []  # subscribers and tokens live as long as the session
        self.published = 0
        self.bytes = 0

    def publish(self, key: str, payload: bytes) -> None:
        publisher = self.publishers.get(key)
        if publisher is None:  # block rather than drop when queues fill: a lost message
            import zenoh  # would cost its receivers a deadline; losses are the fault model's

            publisher = self.publishers[key] = self.session.declare_publisher(
                key,
                congestion_control=zenoh.CongestionControl.BLOCK,
                reliability=zenoh.Reliability.RELIABLE,
            )
        publisher.put(payload)
        self.published += 1
        self.bytes += len(payload)

    def subscribe(self, prefix: str, handler: Callable[[str, bytes], None]) -> None:
        def listener(sample) -> None:
            handler(str(sample.key_expr), sample.payload.to_bytes())

        self.keep.append(self.session.declare_subscriber(expression(prefix), listener))

    def announce(self, key: str) -> None:
        self.keep.append(self.session.liveliness().declare_token(key))

    def watch(self, prefix: str, on_gone: Callable[[str], None]) -> None:
        import zenoh

        def listener(sample) -> None:
            if sample.kind == zenoh.SampleKind.DELETE:
                on_gone(str(sample.key_expr))

        self.keep.append(
            self.session.liveliness().declare_subscriber(
                expression(prefix), listener, history=False
            )
        )

    def alive(self, prefix: str) -> set[str]:
        replies = self.session.liveliness().get(expression(prefix), timeout=1.0)
        return {str(reply.ok.key_expr) for reply in replies if reply.ok is not None}

    def close(self) -> None:
        for item in reversed(self.keep):
            try:
                item.undeclare()
            except Exception:  # already gone with its session
                pass
        self.keep = []
        try:
            self.session.close()
        except Exception:
            pass


class Mailbox:
    """What a program received, decoded and sorted, with waits that have deadlines.

    Radio messages are kept by (cycle, protocol, sender) -> {round: content} and the
    round from which a sender's content is final; others by kind. Malformed, foreign or
    out-of-version messages are counted in `dropped` and forgotten.
    """

    def __init__(self, run: str) -> None:
        self.run = run
        self.cond = threading.Condition()
        self.radio: dict[tuple[int, str, int], dict[int, Any]] = {}
        self.final: dict[tuple[int, str, int], int] = {}
        self.inbox: dict[tuple, Message] = {}
        self.dropped = 0
        self.gone: set[str] = set()

    def handler(self, key: str, payload: bytes) -> None:
        message = decode(payload, self.run)
        with self.cond:
            if message is None:
                self.dropped += 1
            elif isinstance(message, Radio):
                slot = (message.k, message.protocol, message.sender)
                self.radio.setdefault(slot, {})[message.round] = message.content
                if message.final:
                    self.final[slot] = message.round
            else:
                self.inbox[_identity(message)] = message
            self.cond.notify_all()

    def lost(self, key: str) -> None:
        with self.cond:
            self.gone.add(key)
            self.cond.notify_all()

    def content(self, k: int, protocol: str, sender: int, round_: int):
        """The content of a sender's round (or its final content), or None if not here."""
        slot = (k, protocol, sender)
        rounds = self.radio.get(slot)
        if rounds is None:
            return None
        if round_ in rounds:
            return rounds[round_]
        final = self.final.get(slot)
        if final is not None and round_ >= final:
            return rounds[final]
        return None

    def wait(self, ready: Callable[[], bool], deadline: float) -> bool:
        """Wait until ready() holds (checked under the lock) or the deadline passes."""
        with self.cond:
            while not ready():
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self.cond.wait(min(left, 0.5))
            return True

    def take(self, identity: tuple) -> Message | None:
        with self.cond:
            return self.inbox.pop(identity, None)

    def forget(self, before: int) -> None:
        """Drop radio messages of cycles before `before` (no longer needed)."""
        with self.cond:
            for slot in [s for s in self.radio if s[0] < before]:
                self.radio.pop(slot, None)
                self.final.pop(slot, None)


def _identity(message: Message) -> tuple:
    if isinstance(message, Hello):
        return ("hello",)
    if isinstance(message, Sense):
        return ("sense", message.k, message.uav)
    if isinstance(message, Tick):
        return ("tick", message.k)
    return ("report", message.k, message.uav)
