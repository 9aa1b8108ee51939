"""The packed state codec: a /physdbg/state message to and from positions and velocities.

The message's fields and the codecs are the format's (:mod:`.format`, "state codec", and
docs/recording-format.md); this module turns them into bytes and back, through the
protobuf class :mod:`.proto` builds from the format's field list. (It sits above both, so
neither format nor proto imports the other's dependant.)
"""

from __future__ import annotations

import numpy as np

from .format import CODEC_PREVIOUS, CODEC_RAW, CODEC_TWO_PREVIOUS, KEYFRAME_INTERVAL, STATE_MESSAGE
from .proto import encode_state_message as message_bytes, message_class


def _unzigzag(z: np.ndarray) -> np.ndarray:
    return ((z >> np.uint64(1)).view(np.int64)) ^ (-(z & np.uint64(1)).view(np.int64))


def _shuffle(words: np.ndarray) -> bytes:
    return words.view(np.uint8).reshape(-1, 8).T.tobytes()


def _unshuffle(data: bytes | memoryview, count: int) -> np.ndarray:
    planes = np.frombuffer(data, dtype=np.uint8, count=8 * count).reshape(8, count)
    return np.ascontiguousarray(planes.T).view("<u8").reshape(count)


def _predict(codec: int, previous: np.ndarray, before_previous: np.ndarray | None, state: np.ndarray, dt: float,
             scratch: np.ndarray, out: np.ndarray) -> None:
    """Into out (N, 6): a codec's prediction of a state from the frames before (N, 6): the
    velocities v_before (previous) or 2·v_before − v_before_that (two previous), the
    positions x_before + dt·(v_before + v)/2 with v this frame's velocities (state's last
    three columns: the decoder predicts them first). scratch: (N, 6).

    Computed on the flat rows, whole: a position's velocity sits three words after it, so
    the positions' prediction is one shifted operation over 6N words instead of one over
    N rows of 3 (numpy's inner loop of three was 1.3 ms of the 2 ms a 10k state took)."""
    flat_out, flat_scratch = out.reshape(-1), scratch.reshape(-1)
    before, x_and_v = previous.reshape(-1), state.reshape(-1)
    with np.errstate(over="ignore", invalid="ignore"):  # a poor prediction is still lossless
        if codec == CODEC_TWO_PREVIOUS:
            np.multiply(before, 2.0, out=flat_out)
            np.subtract(flat_out, before_previous.reshape(-1), out=flat_out)
        else:
            flat_out[...] = before
        positions = flat_scratch[:-3]  # word 6i + c (c < 3): sphere i's coordinate c
        np.add(before[3:], x_and_v[3:], out=positions)
        np.multiply(positions, dt * 0.5, out=positions)
        np.add(before[:-3], positions, out=positions)
    # the three position words of each row, moved as one 24-byte item (a quarter of the
    # time of a masked or sliced copy of three floats a row)
    out.view("V24").reshape(-1, 2)[:, 0] = scratch.view("V24").reshape(-1, 2)[:, 0]


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
    asleep: (N,) bool, the sleeping spheres, or None when the run does not sleep.
    (A writer of successive frames: StateEncoder, which keeps them itself.)"""
    n = positions.shape[0]
    state = np.empty((n, 6))
    _fill(state, positions, velocities)
    words = _residual_words(codec, state, previous, before_previous, dt, np.empty((n, 6)),
                            np.empty((2, n * 6), dtype=np.int64))
    return _message(frame, time, dt, state_hash, codec, words, asleep)


class StateEncoder:
    """Encodes one run's successive frames (the recorder's), keeping the two states before
    each for the codecs' predictions, and its scratch arrays from frame to frame: at 10,000
    spheres a fresh (N, 6) array costs its page faults, which were a third of encoding a
    state. ``encode`` gives the bytes encode_state gives for the same frames."""

    def __init__(self) -> None:
        self._states: np.ndarray | None = None  # (3, N, 6): the frames k-2, k-1 and k, in turn
        self._prediction: np.ndarray | None = None  # (N, 6) scratch: the predicted state
        self._scratch: np.ndarray | None = None  # (2, N·6) int64 scratch: the residual and its sign
        self._held = 0  # frames before this one held (at most 2)
        self._newest = -1  # the slot of the last frame encoded

    def encode(self, frame: int, time: float, dt: float, state_hash: str, positions: np.ndarray,
               velocities: np.ndarray, asleep: np.ndarray | None = None) -> bytes:
        """Frame ``frame``'s message, with the codec codec_for chooses for it."""
        n = positions.shape[0]
        if self._states is None or self._states.shape[1] != n:
            self._states = np.empty((3, n, 6))
            self._prediction = np.empty((n, 6))
            self._scratch = np.empty((2, n * 6), dtype=np.int64)
            self._held = 0
        codec = codec_for(frame, self._held)
        slot = (self._newest + 1) % 3
        state = self._states[slot]
        _fill(state, positions, velocities)
        previous = self._states[self._newest] if self._held else None
        before = self._states[(self._newest - 1) % 3] if self._held > 1 else None
        words = _residual_words(codec, state, previous, before, dt, self._prediction, self._scratch)
        self._newest = slot
        self._held = min(self._held + 1, 2)
        return _message(frame, time, dt, state_hash, codec, words, asleep)


def _fill(state: np.ndarray, positions: np.ndarray, velocities: np.ndarray) -> None:
    """state (N, 6) = [positions | velocities] ((N, 3) each), each row's three floats moved
    as one 24-byte item (as in _predict)."""
    rows = state.view("V24").reshape(-1, 2)
    rows[:, 0] = np.ascontiguousarray(positions, dtype=np.float64).view("V24").reshape(-1)
    rows[:, 1] = np.ascontiguousarray(velocities, dtype=np.float64).view("V24").reshape(-1)


def _residual_words(codec: int, state: np.ndarray, previous: np.ndarray | None, before_previous: np.ndarray | None,
                    dt: float, prediction: np.ndarray, scratch: np.ndarray) -> np.ndarray:
    """(N·6,) the words a codec writes for ``state`` (N, 6): its float64 bits as they are
    (raw), or their difference from the prediction, zigzagged (into ``scratch`` (2, N·6)
    int64, with ``prediction`` (N, 6) for the predicted state)."""
    words = state.view(np.int64).reshape(-1)
    if codec == CODEC_RAW:
        return words
    _predict(codec, previous, before_previous, state, dt, scratch[1].view(np.float64).reshape(-1, 6), prediction)
    residual, sign = scratch[0], scratch[1]
    np.subtract(words, prediction.view(np.int64).reshape(-1), out=residual)
    np.right_shift(residual, 63, out=sign)  # zigzag ((r << 1) ^ (r >> 63): _unzigzag's inverse), in place
    np.left_shift(residual, 1, out=residual)
    np.bitwise_xor(residual, sign, out=residual)
    return residual.view(np.uint64)


def _message(frame: int, time: float, dt: float, state_hash: str, codec: int, words: np.ndarray,
             asleep: np.ndarray | None) -> bytes:
    return message_bytes(frame, {"time": time, "dt": dt, "state_hash": bytes.fromhex(state_hash), "codec": codec,
                                 "count": words.shape[0] // 6, "words": _shuffle(words),
                                 "asleep": np.packbits(asleep).tobytes() if asleep is not None else b""})


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
    prediction = np.empty((count, 6))
    state = np.zeros((count, 6))
    _predict(codec, previous, before_previous, state, dt, np.empty((count, 6)), prediction)  # the velocities hold
    state[:, 3:] = (prediction[:, 3:].view(np.int64) + residual[:, 3:]).view(np.float64)
    _predict(codec, previous, before_previous, state, dt, np.empty((count, 6)), prediction)  # now the positions do
    state[:, :3] = (prediction[:, :3].view(np.int64) + residual[:, :3]).view(np.float64)
    return state, frame, time, dt, digest, asleep
