"""Sealed messages for a camera network nobody else can read or write: AES-256-GCM with a network key.

The Fast DDS of the PyPI wheels has no security plugins (SROS2 fails), so face-reid secures its own traffic:
every camera frame (and every admin request) is sealed with the network's 32-byte key, shared by the hosts of
one network (``face-reid-keys new``). Sealing encrypts (embeddings are biometric data) and authenticates
(the tag covers the sender id and a counter too): a participant without the key can neither read nor forge.
Freshness and replays are separate checks: a sender's counter is its wall clock in ns (the lowest bits a
per-process random sequence, so that counters are not reused after the clock steps back) and must be within
``max_age_s`` of the receiver's clock; a counter the receiver already saw within that window is refused (a
bounded replay cache per sender, not a high-water mark: one counter far ahead costs the sender nothing, and a
sender whose clock stepped back is heard again at once); and (for a receiver that sets ``not_before_s``, e.g.
its start) it must be newer than the receiver itself, so a message captured before a restart is not accepted
again after it. Pure Python (the ``cryptography`` package), no rclpy.
"""

from __future__ import annotations

import heapq
import os
import stat
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["KEY_BYTES", "Opener", "SealError", "Sealed", "Sealer", "load_network_key", "write_network_key"]

KEY_BYTES = 32  # AES-256
NONCE_BYTES = 12
_MAGIC = b"face-reid-sealed-v1"  # domain separation: a seal made for one purpose is not valid for another
_MAX_SENDER_CHARS = 256
_MAX_SENDERS = 4096  # replay state kept for this many senders (least recently heard forgotten first)
_MAX_SEEN = 1 << 18  # counters remembered at most, all senders together (30 Hz for 60 s is 1,800 per sender)
_SEQ_BITS = 10  # the counter's lowest bits: a per-process sequence instead of the clock's nanoseconds


class SealError(ValueError):
    """A sealed message that must not be used; ``code`` says why (for counters), the message in words."""

    def __init__(self, code: str, message: str) -> None:
        super().__init__(message)
        self.code = code


@dataclass(frozen=True)
class Sealed:
    """What travels: who sealed it, its counter, the nonce and the ciphertext (with the 16-byte tag)."""

    sender_id: str
    counter: int
    nonce: bytes
    ciphertext: bytes


def _aad(purpose: str, sender_id: str, counter: int) -> bytes:
    sender = sender_id.encode("utf-8", "surrogatepass")
    topic = purpose.encode("utf-8", "surrogatepass")
    return _MAGIC + struct.pack("<HH Q", len(topic), len(sender), counter & 0xFFFF_FFFF_FFFF_FFFF) + topic + sender


def _aead(key: bytes) -> Any:
    from cryptography.hazmat.primitives.ciphers.aead import AESGCM

    if len(key) != KEY_BYTES:
        raise ValueError(f"a network key has {KEY_BYTES} bytes, got {len(key)}")
    return AESGCM(key)


@dataclass
class Sealer:
    """Seals payloads of one sender (a camera id, or a client's name) for one ``purpose`` (e.g. "frames")."""

    key: bytes
    sender_id: str
    purpose: str = "frames"
    _seq: int = field(default_factory=lambda: int.from_bytes(os.urandom(2), "little"), repr=False)
    _aes: Any = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if not self.sender_id or len(self.sender_id) > _MAX_SENDER_CHARS:
            raise ValueError(f"sender_id must have 1-{_MAX_SENDER_CHARS} characters, got {len(self.sender_id)}")
        self._aes = _aead(self.key)

    def seal(self, payload: bytes, purpose: str | None = None) -> Sealed:
        """``payload`` sealed for ``purpose`` (default: the sealer's). The counter follows the wall clock, also
        back after a step (no clamp to the last counter: a corrected clock is heard at once); its lowest
        ``_SEQ_BITS`` bits are a sequence from a random start, so counters of one microsecond differ and a
        counter used before a backward step is not met again by chance."""
        self._seq += 1
        mask = (1 << _SEQ_BITS) - 1
        counter = (time.time_ns() & ~mask) | (self._seq & mask)
        nonce = os.urandom(NONCE_BYTES)
        ct = self._aes.encrypt(nonce, payload, _aad(purpose or self.purpose, self.sender_id, counter))
        return Sealed(self.sender_id, counter, nonce, ct)


@dataclass
class _Seen:
    """The counters one sender used within the window (a set, and a heap to prune the oldest), and the newest
    counter pruned (``floor``: a counter at or below it was seen, or is older than the window was)."""

    counters: set[int] = field(default_factory=set)
    heap: list[int] = field(default_factory=list)
    floor: int = 0


@dataclass
class Opener:
    """Checks and opens sealed payloads of one ``purpose``; remembers the counters each sender used within
    ``max_age_s`` (a bounded replay cache, pruned by age).

    ``max_age_s``: a counter (the sender's clock) further than this from the receiver's clock, in either
    direction, is refused (s, > 0): old recordings, and senders whose clock is off. ``not_before_s``: a counter
    older than this wall-clock time (s since the epoch; the receiver's start) is refused as ``replayed``: the
    counters seen die with the process, so without it a message captured before a restart would open again
    after it. The receiver's start is kept on the monotonic clock (``monotonic``) and re-dated by the current
    wall clock at each message, so that it follows a corrected clock (a start dated during a clock glitch
    does not refuse every sender until the glitch's time comes round).
    """

    key: bytes
    purpose: str = "frames"
    max_age_s: float = 30.0
    not_before_s: float = 0.0
    monotonic: Callable[[], float] = field(default=time.monotonic, repr=False)
    _seen: dict[str, _Seen] = field(default_factory=dict, repr=False)
    _seen_total: int = field(default=0, repr=False)
    _not_before_mono: float = field(default=0.0, repr=False)
    _aes: Any = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if not (self.max_age_s > 0):
            raise ValueError(f"max_age_s must be > 0, got {self.max_age_s}")
        self._aes = _aead(self.key)
        # the monotonic time of not_before_s (by the wall clock now)
        self._not_before_mono = self.monotonic() - (time.time() - self.not_before_s)

    def not_before(self, now_s: float) -> float:
        """The wall-clock time (by ``now_s``, this host's clock now) before which counters are refused."""
        if self.not_before_s <= 0:
            return 0.0
        return now_s - (self.monotonic() - self._not_before_mono)

    def open(self, sealed: Sealed, now_s: float | None = None, purpose: str | None = None) -> bytes:
        """The payload sealed for ``purpose`` (default: the opener's), or :class:`SealError` (``forged``,
        ``replayed``, ``stale``, ``malformed``)."""
        from cryptography.exceptions import InvalidTag

        if not sealed.sender_id or len(sealed.sender_id) > _MAX_SENDER_CHARS:
            raise SealError("malformed", f"sender id of {len(sealed.sender_id)} characters")
        if len(sealed.nonce) != NONCE_BYTES or len(sealed.ciphertext) < 16:
            raise SealError("malformed", "nonce or ciphertext of the wrong size")
        if not 0 < sealed.counter < 1 << 64:
            raise SealError("malformed", "counter out of range")
        try:
            payload = self._aes.decrypt(
                sealed.nonce, sealed.ciphertext, _aad(purpose or self.purpose, sealed.sender_id, sealed.counter))
        except (InvalidTag, ValueError, OverflowError) as exc:
            raise SealError("forged", "not sealed with this network's key (or altered on the way)") from exc
        now = time.time() if now_s is None else now_s
        age = now - sealed.counter * 1e-9
        if abs(age) > self.max_age_s:
            raise SealError("stale", f"sealed {age:+.1f} s from this host's clock (more than {self.max_age_s:g} s)")
        start = self.not_before(now)
        if sealed.counter * 1e-9 < start:
            raise SealError("replayed", f"sealed {start - sealed.counter * 1e-9:.1f} s before this "
                                        "receiver started (a replay from before a restart, or a sender's clock behind)")
        seen = self._seen.pop(sealed.sender_id, None) or _Seen()
        self._seen[sealed.sender_id] = seen  # most recently heard last
        self._prune(seen, int((now - self.max_age_s) * 1e9))
        if sealed.counter <= seen.floor or sealed.counter in seen.counters:
            raise SealError("replayed", "a counter this sender already used (a replayed message)")
        seen.counters.add(sealed.counter)
        heapq.heappush(seen.heap, sealed.counter)
        self._seen_total += 1
        while len(self._seen) > _MAX_SENDERS or self._seen_total > _MAX_SEEN:
            self._forget_oldest()
        return payload

    def _prune(self, seen: _Seen, older_than: int) -> None:
        """Forget the sender's counters older than the window (they are stale now); the floor rises to them."""
        while seen.heap and seen.heap[0] < older_than:
            counter = heapq.heappop(seen.heap)
            seen.counters.discard(counter)
            seen.floor = max(seen.floor, counter)
            self._seen_total -= 1

    def _forget_oldest(self) -> None:
        """Memory bound: the oldest counter of the least recently heard sender goes (the floor rises to it);
        a sender with none left is forgotten."""
        sender = next(iter(self._seen))
        seen = self._seen[sender]
        if seen.heap:
            self._prune(seen, seen.heap[0] + 1)
        if not seen.heap:
            del self._seen[sender]


def write_network_key(path: str | Path, overwrite: bool = False) -> Path:
    """A new random network key in ``path`` (mode 0600, parent 0700 if created); refuses to overwrite."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
    flags = os.O_WRONLY | os.O_CREAT | os.O_NOFOLLOW | (os.O_TRUNC if overwrite else os.O_EXCL)
    try:
        fd = os.open(path, flags, 0o600)
    except FileExistsError as exc:
        raise ValueError(f"{path} exists: a network key is not overwritten (face-reid-keys new --force replaces it; "
                         "every host then needs the new key)") from exc
    with os.fdopen(fd, "wb") as f:
        os.fchmod(f.fileno(), 0o600)
        f.write(os.urandom(KEY_BYTES).hex().encode() + b"\n")
    return path


def load_network_key(path: str | Path) -> bytes:
    """The key in ``path``; refuses a missing, symlinked, group/other-readable or malformed file, with why."""
    path = Path(path)
    try:
        st = os.lstat(path)
    except OSError as exc:
        raise ValueError(f"network key {path}: {exc.strerror} (make one with: face-reid-keys new {path})") from exc
    if stat.S_ISDIR(st.st_mode):
        raise ValueError(f"network key {path} is a folder: give the key file in it")
    if stat.S_ISLNK(st.st_mode):
        raise ValueError(f"network key {path} is a symlink: refused (give the file it points to)")
    if not stat.S_ISREG(st.st_mode):
        raise ValueError(f"network key {path} is not a regular file")
    if st.st_mode & 0o077:
        raise ValueError(f"network key {path} is readable by others (mode {st.st_mode & 0o777:o}): chmod 600 it")
    if hasattr(os, "getuid") and st.st_uid != os.getuid():
        raise ValueError(f"network key {path} belongs to another user (uid {st.st_uid})")
    text = path.read_text(errors="replace").strip()
    try:
        key = bytes.fromhex(text)
    except ValueError as exc:
        raise ValueError(f"network key {path} is not {KEY_BYTES * 2} hex digits") from exc
    if len(key) != KEY_BYTES:
        raise ValueError(f"network key {path} is not {KEY_BYTES * 2} hex digits")
    return key
