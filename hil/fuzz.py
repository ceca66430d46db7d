"""The suite's fuzz frames: random and mutated wire frames (``hil.suite.check_fuzz`` sends them)."""

from __future__ import annotations

import numpy as np

from host import protocol as P

# the longest encoded frame is MAX_BODY + 2 bytes (COBS); an oversize run overflows the receiver once to three times
OVERSIZE = (P.MAX_BODY + 4, 3 * (P.MAX_BODY + 3))


def fuzz_frames(n: int, seed: int = 0) -> list[bytes]:
    """Random and mutated wire frames: garbage, bit flips, truncations, wrong lengths, oversize,
    and well-formed frames of every type with random payloads (arguments that would make the
    device busy for long, BENCH n and STREAM counts, kept small)."""
    rng = np.random.default_rng(seed)
    frames = []
    types = [int(t) for t in P.MsgType] + [0x00, 0x0B, 0x7F, 0x80, 0xFF]
    for i in range(n):
        kind = i % 6
        t = int(rng.choice(types))
        payload = rng.bytes(int(rng.integers(0, 300)))
        if t == P.MsgType.BENCH:
            payload = int(rng.integers(0, 64)).to_bytes(4, "little")
        elif t == P.MsgType.STREAM:
            payload = int(rng.integers(0, 3)).to_bytes(2, "little") + int(rng.integers(0, 3)).to_bytes(2, "little")
        seq = int(rng.integers(1, 256))
        body = bytes([t & 0xFF, seq]) + len(payload).to_bytes(2, "little") + payload
        body += P.crc32(body).to_bytes(4, "little")
        if kind == 0:  # garbage, delimited
            frames.append(rng.bytes(int(rng.integers(1, 80))) + b"\x00")
        elif kind == 1:  # a valid frame with flipped bits
            enc = bytearray(P.cobs_encode(body))
            for _ in range(int(rng.integers(1, 4))):
                enc[int(rng.integers(len(enc)))] ^= 1 << int(rng.integers(8))
            frames.append(bytes(enc) + b"\x00")
        elif kind == 2:  # truncated
            enc = P.cobs_encode(body)
            frames.append(enc[: int(rng.integers(0, len(enc)))] + b"\x00")
        elif kind == 3:  # length field disagreeing with the payload, CRC made right
            wrong = bytearray(body[:-4])
            wrong[2:4] = int(rng.integers(0, 65536)).to_bytes(2, "little")
            frames.append(P.cobs_encode(bytes(wrong) + P.crc32(bytes(wrong)).to_bytes(4, "little")) + b"\x00")
        elif kind == 4:  # oversize: no delimiter for longer than the longest frame, up to three of them
            size = int(rng.integers(OVERSIZE[0], OVERSIZE[1]))
            frames.append(bytes(rng.integers(1, 256, size, dtype=np.uint8)) + b"\x00")
        else:  # well formed, random type and payload (may be refused for its length or arguments)
            frames.append(P.cobs_encode(body) + b"\x00")
    return frames
