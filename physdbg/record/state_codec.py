"""The packed state codec: a /physdbg/state message to and from positions and velocities.

The message's fields and the codecs are the format's (:mod:`.format`, "state codec", and
docs/recording-format.md); this module turns them into bytes and back, through the
protobuf class :mod:`.proto` builds from the format's field list. (It sits above both, so
neither format nor proto imports the other's dependant.)
"""

from __future__ import annotations

import numpy as np

from .format import CODEC_PREVIOUS, CODEC_RAW, CODEC_TWO_PREVIOUS, KEYFRAME_INTERVAL, STATE_MESSAGE
from .proto import message_class


def _zigzag(r: np.ndarray) -> np.ndarray:
    return ((r << 1) ^ (r >> 63)).view(np.uint64)


def _unzigzag(z: np.ndarray) -> np.ndarray:
    return ((z >> np.uint64(1)).view(np.int64)) ^ (-(z & np.uint64(1)).view(np.int64))


def _shuffle(words: np.ndarray) -> bytes:
    return words.view(np.uint8).reshape(-1, 8).T.tobytes()


def _unshuffle(data: bytes | memoryview, count: int) -> np.ndarray:
    planes = np.frombuffer(data, dtype=np.uint8, count=8 * count).reshape(8, count)
    return np.ascontiguousarray(planes.T).view("<u8").reshape(count)


def _velocity_prediction(codec: int, previous: np.ndarray, before_previous: np.ndarray | None) -> np.ndarray:
    if codec == CODEC_TWO_PREVIOUS:
        with np.errstate(over="ignore", invalid="ignore"):  # a poor prediction is still lossless
            return 2.0 * previous[:, 3:] - before_previous[:, 3:]
    return previous[:, 3:].copy()


def codec_for(frame: int, have_previous: int) -> int:
    """Which codec the writer uses at ``frame`` given how many earlier frames it holds."""
    if frame % KEYFRAME_INTERVAL == 0 or have_previous == 0:
        return CODEC_RAW
    if frame % KEYFRAME_INTERVAL == 1 or have_previous == 1:
        return CODEC_PREVIOUS
    return CODEC_TWO_PREVIOUS


def encode_state(frame: int, time: float, dt: float, state_hash: str, positions: np.ndarray,
                 velocities: np.ndarray, codec: int, previous: np.ndarray | None = None,
                 before_previous: np.ndarray | None = None, asleep: np.ndarray | None = None) -> bytes:
    """One /physdbg/state message. positions, velocities: (N, 3) float64; previous,
    before_previous: (N, 6) float64 states of frames k-1 and k-2 (as codec needs);
    asleep: (N,) bool, the sleeping spheres, or None when the run does not sleep."""
    n = positions.shape[0]
    state = np.empty((n, 6))
    state[:, :3] = positions
    state[:, 3:] = velocities
    words = state.view(np.int64).copy()
    if codec != CODEC_RAW:
        v_pred = _velocity_prediction(codec, previous, before_previous)
        with np.errstate(over="ignore", invalid="ignore"):
            x_pred = previous[:, :3] + (dt * 0.5) * (previous[:, 3:] + velocities)
        words[:, :3] -= x_pred.view(np.int64)
        words[:, 3:] -= v_pred.view(np.int64)
        words = _zigzag(words)
    message = message_class(STATE_MESSAGE)(step=frame, time=time, dt=dt, state_hash=bytes.fromhex(state_hash),
                                           codec=codec, count=n, words=_shuffle(words.reshape(-1)),
                                           asleep=np.packbits(asleep).tobytes() if asleep is not None else b"")
    return message.SerializeToString()


def decode_state_header(data: bytes):
    """The parsed physdbg.State message (step, time, dt, state_hash, codec, count, words);
    ValueError if it is not one."""
    from google.protobuf.message import DecodeError

    try:
        message = message_class(STATE_MESSAGE).FromString(data)
    except DecodeError as err:
        raise ValueError(f"not a physdbg state message ({err})") from None
    if message.codec > CODEC_TWO_PREVIOUS or len(message.state_hash) != 16:
        raise ValueError("not a physdbg state message (bad codec or hash)")
    if len(message.words) != 48 * message.count:
        raise ValueError(f"state words of {len(message.words)} bytes, expected {48 * message.count}")
    if message.asleep and len(message.asleep) != (message.count + 7) // 8:
        raise ValueError(f"asleep mask of {len(message.asleep)} bytes, expected {(message.count + 7) // 8}")
    return message


def decode_state(data: bytes, previous: np.ndarray | None = None, before_previous: np.ndarray | None = None
                 ) -> tuple[np.ndarray, int, float, float, str, np.ndarray | None]:
    """(state (N, 6) float64, frame, time, dt, state_hash, asleep) of a state message;
    asleep: (N,) bool, or None when the run did not let spheres sleep.

    previous / before_previous: decoded (N, 6) states of the frames before, as the
    message's codec needs (ValueError if missing).
    """
    m = decode_state_header(data)
    codec, count, frame, time, dt, digest = m.codec, m.count, m.step, m.time, m.dt, m.state_hash.hex()
    asleep = (np.unpackbits(np.frombuffer(m.asleep, np.uint8), count=count).astype(bool) if m.asleep
              else None)
    words = _unshuffle(m.words, 6 * count).reshape(count, 6)
    if codec == CODEC_RAW:
        return words.view(np.float64).copy(), frame, time, dt, digest, asleep
    if previous is None or (codec == CODEC_TWO_PREVIOUS and before_previous is None):
        raise ValueError(f"frame {frame} needs the frames before it to decode")
    residual = _unzigzag(words)
    v_pred = _velocity_prediction(codec, previous, before_previous)
    state = np.empty((count, 6))
    state[:, 3:] = (v_pred.view(np.int64) + residual[:, 3:]).view(np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        x_pred = previous[:, :3] + (dt * 0.5) * (previous[:, 3:] + state[:, 3:])
    state[:, :3] = (x_pred.view(np.int64) + residual[:, :3]).view(np.float64)
    return state, frame, time, dt, digest, asleep
